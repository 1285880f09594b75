"""Arm renders: frames, MP4 and plots are written headless and have the expected content."""

from __future__ import annotations

import cv2
import numpy as np

from physanim.muscle.arm import solve_arm
from physanim.muscle.params import ArmStudyParams
from physanim.render.arm import (
    plot_condition_summary,
    plot_muscle_curves,
    plot_muscle_timeseries,
    render_arm_video,
)


def test_arm_video_and_plots(tmp_path):
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
    for p in (
        plot_muscle_timeseries({"load": res}, s.arm, tmp_path / "a.png", "activation"),
        plot_muscle_timeseries({"load": res}, s.arm, tmp_path / "l.png", "fibre_length"),
        plot_muscle_curves(tmp_path / "c.png"),
        plot_condition_summary({"load": res}, ["shoulder", "elbow"], tmp_path / "s.png"),
    ):
        assert cv2.imread(str(p)) is not None
