"""Shared fixtures: a toy dataset and its config; a coarse face demo run by the CLI."""

from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.commands import ROOT, physanim

#: Overlay config for short, coarse face runs (relative to the repository root)
COARSE = "tests/face_pipeline/coarse.yaml"

# the Prefect servers that the CLI runs of the tests share stop soon after the last one
os.environ.setdefault("PHYSANIM_PREFECT_IDLE_S", "30")


@pytest.fixture
def toy_config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A default config for the toy DAG whose store lives in tmp_path; logs executions."""
    cfg = tmp_path / "toy.yaml"
    cfg.write_text(
        f"dataset:\n  name: toy\n  dir: {tmp_path / 'data'}\n"
        "source:\n  n_frames: 8\nscale:\n  factor: 2.0\n"
    )
    monkeypatch.setenv("PHYSANIM_TOY_LOG", str(tmp_path / "executions.log"))
    return cfg


@contextlib.contextmanager
def repo_data_folder() -> Iterator[Path]:
    """A new folder ``data/pytest-<pid>-<random>`` (relative to the repository root, where
    the README's commands run), removed at the end."""
    folder = Path("data") / f"pytest-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    (ROOT / folder).mkdir(parents=True)
    try:
        yield folder
    finally:
        shutil.rmtree(ROOT / folder, ignore_errors=True)


@pytest.fixture
def data_folder() -> Iterator[Path]:
    """A folder under data/, relative to the repository root; removed after the test."""
    with repo_data_folder() as folder:
        yield folder


@pytest.fixture(scope="session")
def face_demo() -> Iterator[tuple[Path, str]]:
    """A coarse 12-frame face demo, made and run by the README's command from the repository
    root with relative paths: ``physanim run --dataset data/pytest-.../demo -c COARSE``.

    Yields (dataset directory relative to the repository root, the run's stderr); the folder
    is removed at the end of the session.
    """
    with repo_data_folder() as folder:
        data = folder / "demo"
        out = physanim("run", "--dataset", str(data), "-c", COARSE)
        assert out.returncode == 0, out.stderr[-3000:]
        yield data, out.stderr
