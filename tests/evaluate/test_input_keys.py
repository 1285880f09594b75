"""Every input file a stage reads is part of its key: editing it re-runs the stage."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import zarr

from flows.dags import FACE
from physanim.pipeline import DatasetParams
from physanim.pipeline.plan import key_params
from physanim.store import stage_key, write_array


def key(stage: str, dataset: DatasetParams, **params: object) -> str:
    spec = FACE.stage(stage)
    validated = spec.params.model_validate(params)
    return stage_key(stage, spec.version, key_params(spec, dataset, validated), {})


def touch_later(path: Path) -> None:
    """Give ``path`` a later modification time (an editor saving the same size)."""
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))


def test_edited_ground_truth_changes_the_evaluate_key(tmp_path: Path) -> None:
    dataset = DatasetParams(dir=str(tmp_path))
    without = key("evaluate", dataset)
    truth = zarr.open_group(tmp_path / "ground_truth.zarr", mode="w")
    write_array(truth, "faces", np.zeros((4, 3), np.int64))
    created = key("evaluate", dataset)
    truth["faces"][...] = np.ones((4, 3), np.int64)  # same size, new content
    chunk = next(p for p in (tmp_path / "ground_truth.zarr" / "faces").rglob("*") if p.is_file()
                 and p.name != "zarr.json")  # fmt: skip
    touch_later(chunk)
    edited = key("evaluate", dataset)
    assert len({without, created, edited}) == 3
    assert key("evaluate", dataset) == edited  # nothing changed: same key


@pytest.mark.parametrize(
    ("stage", "relative", "params"),
    [
        ("track", "stereo/calibration.yaml", {"lift": "stereo"}),
        ("scan", "scan.ply", {}),
    ],
)
def test_edited_input_file_changes_the_key(tmp_path, stage, relative, params) -> None:
    path = tmp_path / relative
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("one\n")
    if stage == "scan":
        params = {"scan": str(path)}
    dataset = DatasetParams(dir=str(tmp_path))
    before = key(stage, dataset, **params)
    touch_later(path)
    assert key(stage, dataset, **params) != before
