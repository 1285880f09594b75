"""Fixtures of the reliability tests: a toy store run by the CLI, copies of the face demo."""

from __future__ import annotations

import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from physanim.store import StageStore
from tests.commands import ROOT


def assert_store_tells_the_truth(store: StageStore) -> None:
    """Every group at a final path is intact (all files, sizes and checksums), no group reads
    as complete unless it is, and every recorded run's outputs were computed from each other."""
    for stage in store.stages():
        for key in store.all_keys(stage):
            assert store.damage(stage, key, checksums=True) is None, (stage, key)
    for run in store.runs():
        for stage, key in run.keys.items():
            if store.has(stage, key):
                upstream = store.provenance(stage, key)["upstream"]
                assert all(run.keys.get(u) == k for u, k in upstream.items()), (run.name, stage)


@pytest.fixture
def face_copy(face_demo) -> Iterator[Path]:
    """A private copy of the session's coarse face demo (inputs and store, not Prefect's
    home), relative to the repository root under data/; removed afterwards."""
    data, _ = face_demo
    folder = data.parent / f"copy-{uuid.uuid4().hex[:6]}"
    shutil.copytree(ROOT / data, ROOT / folder / "demo", ignore=shutil.ignore_patterns("prefect"))
    try:
        yield folder / "demo"
    finally:
        shutil.rmtree(ROOT / folder, ignore_errors=True)
