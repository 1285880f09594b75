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
