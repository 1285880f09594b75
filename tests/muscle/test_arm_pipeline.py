"""The arm pipeline end to end (local runner): stored arrays, renders, cache behaviour."""

from __future__ import annotations

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
