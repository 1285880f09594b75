"""The ingest stage in the face DAG: stored arrays, caching and what a stereo edit re-runs."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from flows.dags import FACE
from physanim.config import load_config
from physanim.pipeline import execute_plan_locally, make_plan
from physanim.store import StageStore
from tests.capture.conftest import N_FRAMES


def plan_for(demo_dir: Path, store: Path, *sets: str):
    base = [f"dataset.dir={demo_dir}", f"dataset.store={store}", "ingest.source=stereo"]
    cfg, _ = load_config(FACE.config_model(), [FACE.default_config], base + list(sets))
    return cfg, make_plan(FACE, cfg, StageStore(cfg.dataset.store_path))


def test_ingest_stage_caches_and_reruns_on_stereo_edit(demo_dir: Path, tmp_path: Path) -> None:
    store_path = tmp_path / "store.zarr"
    cfg, plan = plan_for(demo_dir, store_path)
    assert [(e.stage, e.action) for e in plan][:1] == [("ingest", "run")]
    execute_plan_locally(FACE, cfg, plan[:1])

    out = StageStore(store_path).open("ingest")
    assert out["color"].shape == (N_FRAMES, 480, 640, 3) and out["color"].dtype == np.uint8
    assert out["color"].chunks[0] < N_FRAMES or N_FRAMES <= 4  # chunked by frames
    depth = out["depth"][...]
    assert depth.dtype == np.float32 and np.isnan(depth).any() and np.nanmedian(depth) > 0.3
    assert out.attrs["summary"]["source"].startswith("stereo")

    _, again = plan_for(demo_dir, store_path)
    assert again[0].action == "cached"
    _, edited = plan_for(demo_dir, store_path, "ingest.block_size=7")
    assert edited[0].action == "run" and "ingest.block_size: 5 -> 7" in edited[0].reason


def test_dataset_root_layout_caches_and_track_runs_after_ingest(
    demo_dir: Path, tmp_path: Path
) -> None:
    """color/, depth/, intrinsic.json at the dataset root, the store inside it (the default
    data/<name>/runs/store.zarr): ingest's key depends on exactly its input files, so the
    run directory growing does not make it run again."""
    root = tmp_path / "mine"
    shutil.copytree(demo_dir / "rgbd", root)
    shutil.copytree(demo_dir / "ground_truth.zarr", root / "ground_truth.zarr")
    sets = [f"dataset.dir={root}"]
    cfg, _ = load_config(FACE.config_model(), [FACE.default_config], sets)
    assert cfg.dataset.store_path == root / "runs" / "store.zarr"
    store = StageStore(cfg.dataset.store_path)
    plan = make_plan(FACE, cfg, store, only="ingest")
    assert [e.action for e in plan if e.stage == "ingest"] == ["run"]
    execute_plan_locally(FACE, cfg, plan)
    again = {e.stage: e for e in make_plan(FACE, cfg, store, only="track")}
    assert again["ingest"].action == "cached", again["ingest"].reason
    results = execute_plan_locally(FACE, cfg, list(again.values()))
    assert [(r.stage, r.action) for r in results] == [("ingest", "cached"), ("track", "ran")]
    final = {e.stage: e.action for e in make_plan(FACE, cfg, store)}
    assert final["ingest"] == final["track"] == "cached"
    (root / "depth" / "000002.png").touch()  # an edited input file does change the key
    os.utime(root / "depth" / "000002.png", ns=(1, 1))
    assert make_plan(FACE, cfg, store)[0].action == "run"
