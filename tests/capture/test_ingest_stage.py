"""The ingest stage in the face DAG: stored arrays, caching and what a stereo edit re-runs."""

from __future__ import annotations

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
