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
from physanim.muscle.arm import ArmResult, solve_arm
from physanim.pipeline import execute_plan_locally, make_plan
from physanim.store import StageStore, read_dataclass


def test_arm_pipeline_stores_conditions_and_renders(tmp_path: Path) -> None:
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
    assert (files / "activation.png").stat().st_size > 10_000

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
    assert any(
        "J1 (forearm) from 280 to 610 ms; up to 5.50 N m of flexion missing" in w for w in warnings
    ), warnings
    assert any("J0 (upper_arm) from 0 to 620 ms; up to 15.43 N m" in w for w in warnings)
    summary = StageStore(tmp_path / "runs" / "store.zarr").open("muscles").attrs["summary"]
    assert summary["feasible"] is False and set(summary["infeasible"]) == {"load_1kg"}
