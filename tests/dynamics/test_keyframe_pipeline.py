"""The keyframe pipeline (local runner): stored animation, video, file-content caching."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np

from flows.dags import KEYFRAME
from physanim.config import load_config
from physanim.pipeline import execute_plan_locally, make_plan
from physanim.store import StageStore

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_keyframe_pipeline_renders_and_tracks_file_content(tmp_path: Path) -> None:
    keys = tmp_path / "keyframes" / "jump.yaml"
    keys.parent.mkdir()
    shutil.copy(CONFIGS / "keyframes" / "jump.yaml", keys)
    shutil.copytree(CONFIGS / "figures", tmp_path / "figures")
    sets = [f"dataset.dir={tmp_path / 'run'}", f"keyframes.file={keys}"]
    cfg, _ = load_config(KEYFRAME.config_model(), [KEYFRAME.default_config], sets)
    store = StageStore(cfg.dataset.store_path)
    execute_plan_locally(KEYFRAME, cfg, make_plan(KEYFRAME, cfg, store))

    anim = store.open("keyframes")
    assert anim["q"].shape == (31, 30)  # 31 frames, 30 DOF
    assert float(np.min(anim["placement/distance"][...])) > -1e-3  # no penetration > 1 mm
    video = cv2.VideoCapture(
        str(Path(store.open("keyframe_render").store.root) / "files" / "animation.mp4")
    )
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 31

    assert [e.action for e in make_plan(KEYFRAME, cfg, store)] == ["cached", "cached"]
    keys.write_text(keys.read_text().replace("frame: 30", "frame: 32"))  # edit the file
    plan = make_plan(KEYFRAME, cfg, store)
    assert [e.action for e in plan] == ["run", "run"] and "inputs.jump.yaml" in plan[0].reason


def test_walk_demo_along_a_root_path_is_rendered(tmp_path: Path) -> None:
    """configs/keyframe_walk.yaml as shipped: the figure walks the curved path, rendered."""
    cfg, _ = load_config(
        KEYFRAME.config_model(),
        [KEYFRAME.default_config, CONFIGS / "keyframe_walk.yaml"],
        [f"dataset.dir={tmp_path}"],
    )
    store = StageStore(cfg.dataset.store_path)
    execute_plan_locally(KEYFRAME, cfg, make_plan(KEYFRAME, cfg, store))
    anim = store.open("keyframes")
    assert anim["q"].shape == (49, 30)
    base = anim["placement/base_pos"][...]
    np.testing.assert_allclose(base[-1, [0, 2]], [1.2, 1.2], atol=1e-12)  # the last point
    assert abs(anim["placement/distance"][...]).max() < 1e-9  # feet on the ground
    assert anim.attrs["summary"]["path_length_m"] > 1.7
    files = Path(store.open("keyframe_render").store.root) / "files"
    video = cv2.VideoCapture(str(files / "animation.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 49
    first = cv2.imread(str(files / "frames" / "frame_0000.png"))
    last = cv2.imread(str(files / "frames" / "frame_0048.png"))
    assert np.abs(first.astype(int) - last).sum() > 0  # the figure moved
