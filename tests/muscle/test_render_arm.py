"""Arm renders: frames, MP4 and plots are written headless and have the expected content."""

from __future__ import annotations

import cv2
import numpy as np
from matplotlib.figure import Figure

from physanim.muscle.arm import solve_arm
from physanim.muscle.params import ArmStudyParams
from physanim.render.arm import (
    plot_condition_summary,
    plot_muscle_curves,
    plot_muscle_timeseries,
    render_arm_video,
)


def test_arm_video_and_plots(tmp_path, monkeypatch):
    s = ArmStudyParams.model_validate({"arm": {"load_mass": 1.0}, "motion": {"sample_rate": 20}})
    res = solve_arm(s)
    video = render_arm_video(res, s.arm, s.shape, tmp_path / "frames", fps=10, size_px=200)
    frames = sorted((tmp_path / "frames").glob("frame_*.png"))
    assert len(frames) == 11  # 0..1000 ms at 10 frames/s
    cap = cv2.VideoCapture(str(video))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 11
    ok, img = cap.read()
    assert ok and img.shape[:2] == (200, 200)
    # the most active muscle at t = 0 is drawn red-ish: (B, G, R) with R high, G and B low
    first = cv2.imread(str(frames[0])).reshape(-1, 3).astype(int)
    assert res.activation[0].max() > 0.5
    assert np.any((first[:, 2] > 200) & (first[:, 1] < 150) & (first[:, 0] < 150))
    # a colour bar (white to red, top = 1) in the right margin; the names in a key below
    # (colour bar axes: x 0.86-0.895, y 0.12-0.82 of the 200 px frame)
    column = first.reshape(200, 200, 3)[40:174, 175]
    assert column[0, 2] > 200 and column[0, 1] < 60  # red at the top
    assert column[-1].min() > 230  # white at the bottom
    assert np.abs(np.diff(column[:, 1])).max() < 40  # a smooth ramp, not a blank strip

    saved = []
    real_savefig = Figure.savefig
    monkeypatch.setattr(
        Figure, "savefig", lambda f, *a, **k: (saved.append(f), real_savefig(f, *a, **k))
    )
    for p in (
        plot_muscle_timeseries({"load": res}, s.arm, tmp_path / "a.png", "activation"),
        plot_muscle_timeseries({"load": res}, s.arm, tmp_path / "l.png", "fibre_length"),
        plot_muscle_curves(tmp_path / "c.png"),
        plot_condition_summary({"load": res}, ["shoulder", "elbow"], tmp_path / "s.png"),
    ):
        assert cv2.imread(str(p)) is not None
    panels = [ax for f in saved for ax in f.axes if ax.axison]
    assert len(panels) == 4 + 4 + 3 + 3
    for ax in panels:  # every panel titled, every axis labelled with its unit
        assert ax.get_title()
        assert "(" in ax.get_xlabel() and "(" in ax.get_ylabel(), ax.get_title()
