"""Shared fixtures: a temporary working copy of a toy dataset and its config."""

from __future__ import annotations

from pathlib import Path

import pytest


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
