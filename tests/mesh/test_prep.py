"""Scan preparation of face000: one component, one border, target size; unit mistakes caught."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from physanim.mesh.remesh import border_loop_sizes, remesh_isotropic


def test_face000_prep_is_one_sheet_of_the_target_size(skin):
    v, f = skin
    adj = sp.coo_array(
        (np.ones(f.size), (f.ravel(), np.roll(f, 1, axis=1).ravel())), shape=(len(v), len(v))
    )
    n_comp, _ = connected_components(adj, directed=False)
    assert n_comp == 1
    assert len(border_loop_sizes(f)) == 1  # inner holes closed: a disc, watertight-able
    assert 20_000 <= len(v) <= 30_000
    edge = np.linalg.norm(v[f[:, 0]] - v[f[:, 1]], axis=1)
    assert abs(np.median(edge) - 0.7e-3) < 0.15e-3


def test_scan_in_mm_is_caught_with_a_clear_error(actor):
    with pytest.raises(ValueError, match="not in metres"):
        remesh_isotropic(actor.vertices * 1e3, actor.faces, 0.7e-3)


def test_edge_length_given_in_mm_is_caught(actor):
    with pytest.raises(ValueError, match="edge_length_m"):
        remesh_isotropic(actor.vertices, actor.faces, 0.9)


def test_the_demo_actor_is_the_same_bytes_in_every_process() -> None:
    """Open3D's ICP (the actor's symmetry plane) sums over threads in no fixed order; the
    plane is rounded so the actor, and the scan stage made from it, does not change from run
    to run (three processes gave three remeshed scans of 27,790-27,794 vertices before)."""
    import subprocess
    import sys

    code = (
        "import hashlib; from physanim.capture.actor import build_actor; a = build_actor(); "
        "print(hashlib.sha256(a.vertices.tobytes() + a.faces.tobytes()).hexdigest())"
    )
    digests = {
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        ).stdout.strip()
        for _ in range(3)
    }
    assert len(digests) == 1, digests
