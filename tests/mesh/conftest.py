"""Shared fixtures: the prepared face000 skin (actor frame, metres) and its feature points."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.capture.actor import Actor, build_actor
from physanim.capture.markers import place_markers
from physanim.face.landmarks import FEATURE_POINTS
from physanim.mesh.params import ScanParams
from physanim.mesh.remesh import prepare_scan


@pytest.fixture(scope="session")
def actor() -> Actor:
    """The cleaned face000 scan in the actor frame (capture helper's demo actor)."""
    return build_actor()


@pytest.fixture(scope="session")
def skin(actor: Actor) -> tuple[np.ndarray, np.ndarray]:
    """face000 prepared with the default ScanParams: (V (N, 3) m, F (M, 3))."""
    p = ScanParams()
    return prepare_scan(actor.vertices, actor.faces, p.remesh_edge_length_m, p.remesh_iterations)


@pytest.fixture(scope="session")
def landmarks(skin: tuple[np.ndarray, np.ndarray]) -> dict[str, np.ndarray]:
    """Feature points on the prepared skin, name -> (3,) metres."""
    v, f = skin
    markers = place_markers(v, f)
    pos = markers.positions(v, f)
    return {n: pos[markers.names.index(n)] for n in FEATURE_POINTS}
