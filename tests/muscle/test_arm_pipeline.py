"""The arm pipeline end to end (local runner): stored arrays, renders, cache behaviour."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from flows.dags import ARM
from physanim.config import load_config
from physanim.muscle.arm import ArmResult, solve_arm, torque_shortfalls
from physanim.pipeline import execute_plan_locally, make_plan
from physanim.store import StageStore, read_dataclass
from tests.render.plot_content import (
    assert_not_blank,
    capture_figures,
    curve_drawn,
    read_rgb,
    to_pixels,
)


def test_arm_pipeline_stores_conditions_and_renders(tmp_path: Path, monkeypatch) -> None:
    saved = capture_figures(monkeypatch)
    sets = [f"dataset.dir={tmp_path}", "arm_render.fps=5", "arm_render.size_px=160"]
    cfg, _ = load_config(ARM.config_model(), [ARM.default_config], sets)
    store = StageStore(cfg.dataset.store_path)
    results = execute_plan_locally(ARM, cfg, make_plan(ARM, cfg, store))
    assert [r.action for r in results] == ["ran", "ran"]

    stored = read_dataclass(ArmResult, store.open("muscles")["load_1kg"])
    direct = solve_arm(cfg.muscles.resolved()["load_1kg"])
    np.testing.assert_array_equal(stored.activation, direct.activation)
    assert abs(stored.torque_residual).max() < 1e-6
    summary = store.open("muscles").attrs["summary"]
    assert summary["feasible"] is True and summary["infeasible"] == {}
    assert "warnings" not in summary

    files = Path(store.open("arm_render").store.root) / "files"
    video = cv2.VideoCapture(str(files / "free" / "arm.mp4"))
    n = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
    ok, frame = video.read()
    assert ok and n == 6 and frame.shape[:2] == (160, 160)  # 1 s at 5 fps, both ends
    assert frame.std() > 5  # not a blank image
    # the activation plot: one panel per muscle, one line per condition, each drawn where the
    # stored activations put it
    fig = next(f for f, p in saved if p.name == "activation.png")
    img = read_rgb(files / "activation.png")
    assert_not_blank(img)
    muscles = [m.name for m in cfg.muscles.base.arm.muscles]
    conditions = list(cfg.muscles.resolved())
    for k, ax in enumerate(fig.axes[: len(muscles)]):
        assert ax.get_title().startswith(muscles[k])
        lines = {ln.get_label(): ln.get_color() for ln in ax.get_lines()}
        assert list(lines) == conditions
        act = {
            c: read_dataclass(ArmResult, store.open("muscles")[c]).activation[:, k]
            for c in conditions
        }
        time_ms = 1000 * read_dataclass(ArmResult, store.open("muscles")["free"]).time
        rows = {c: to_pixels(img, fig, ax, time_ms, act[c])[0] for c in conditions}
        for n, c in enumerate(conditions):  # points under a later line (within 3 px) are hidden
            later = [np.abs(rows[c] - rows[d]) <= 3 for d in conditions[n + 1 :]]
            covered = np.any(later, axis=0) if later else None
            drawn = curve_drawn(img, fig, ax, time_ms, act[c], lines[c], covered=covered)
            assert drawn > 0.95, (muscles[k], c, drawn)

    # only the render re-runs when a render setting changes
    sets[1] = "arm_render.fps=4"
    cfg, _ = load_config(ARM.config_model(), [ARM.default_config], sets)
    plan = make_plan(ARM, cfg, store)
    assert [e.action for e in plan] == ["cached", "run"]


def test_cli_warns_of_torque_the_muscles_cannot_produce(tmp_path: Path) -> None:
    """5 kg in the hand: the CLI names condition, joint, time span and missing torque, and
    the stored summary flags it."""
    root = Path(__file__).resolve().parents[2]
    readme = "run -p arm --local --only muscles --set muscles.conditions.load_1kg.arm.load_mass=5.0"
    run = subprocess.run(  # the README's command, writing to a temporary dataset directory
        [sys.executable, "-m", "cli", *readme.split(), "--set", f"dataset.dir={tmp_path}"],
        cwd=root,
        env={**os.environ, "COLUMNS": "250"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    warnings = [ln for ln in run.stderr.splitlines() if ln.startswith("warning:")]  # console
    assert warnings and all("'load_1kg'" in w for w in warnings)
    # one line per span the solver finds, its numbers as the solver has them (the solver's
    # missing torque is checked against an independent derivation in test_muscle.py)
    cfg, _ = load_config(ARM.config_model(), [ARM.default_config], [readme.split("--set ")[1]])
    heavy = cfg.muscles.resolved()["load_1kg"]
    joints = [f"J{j} ({link.name})" for j, link in enumerate(heavy.arm.links)]
    gaps = torque_shortfalls(solve_arm(heavy), joints)
    assert len(warnings) == len(gaps) and {g.joint for g in gaps} == set(joints)
    for g, w in zip(gaps, warnings, strict=True):
        kind = "flexion" if g.peak_Nm > 0 else "extension"
        span = f"{1000 * g.start_s:.0f} to {1000 * g.end_s:.0f} ms"
        assert f"{g.joint} from {span}; up to {abs(g.peak_Nm):.2f} N m of {kind} missing" in w, w
    summary = StageStore(tmp_path / "runs" / "store.zarr").open("muscles").attrs["summary"]
    assert summary["feasible"] is False and set(summary["infeasible"]) == {"load_1kg"}
