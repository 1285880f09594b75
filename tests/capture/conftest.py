"""A short demo dataset generated once per test session."""

from __future__ import annotations

from pathlib import Path

import pytest
import zarr

from physanim.capture.demo import generate_demo

N_FRAMES = 6


@pytest.fixture(scope="session")
def demo_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Directory of a 6-frame demo dataset (seed 0, 30 fps)."""
    return generate_demo(tmp_path_factory.mktemp("capture") / "demo", n_frames=N_FRAMES, seed=0)


@pytest.fixture(scope="session")
def ground_truth(demo_dir: Path) -> zarr.Group:
    return zarr.open_group(demo_dir / "ground_truth.zarr", mode="r")
