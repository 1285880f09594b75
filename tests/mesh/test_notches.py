"""Zipping border notches (scanner slits) of a surface shut."""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from physanim.mesh.notches import border_loops, close_border_notches
from physanim.mesh.topology import watertight_problems


def sheet_with_slit(width_m: float, depth_m: float = 0.02):
    """A 6 x 6 cm grid sheet with a slit of ``width_m`` cut up from its bottom border,
    ``depth_m`` long, its two sides at different depths (z) like a crease."""
    xs, ys = np.linspace(-0.03, 0.03, 61), np.linspace(-0.03, 0.03, 61)
    g = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    faces = Delaunay(g).simplices
    centroids = g[faces].mean(axis=1)
    slit = (np.abs(centroids[:, 0]) < width_m / 2) & (centroids[:, 1] < -0.03 + depth_m)
    faces = faces[~slit]
    used, faces = np.unique(faces, return_inverse=True)
    faces = faces.reshape(-1, 3)
    g = g[used]
    z = np.where(g[:, 0] > 0, -0.004, 0.0) * (g[:, 1] < -0.03 + depth_m)  # a 4 mm step
    v = np.c_[g, z]
    e = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    faces[e[:, 2] < 0] = faces[e[:, 2] < 0][:, ::-1]  # normals to +z
    return v, faces


def test_narrow_slit_is_zipped_into_one_manifold_border() -> None:
    v, f = sheet_with_slit(0.003)
    before = border_loops(f)
    closed, n = close_border_notches(v, f, max_gap_m=0.006, min_depth_m=0.008)
    after = border_loops(closed)
    assert n == 1 and len(after) == 1
    assert len(after[0]) < len(before[0]) - 30  # the slit's two sides left the border
    assert watertight_problems(closed) == [f"{len(after[0])} open (border) edges"]
    # the new triangles span the slit only: none longer than the gap across a 4 mm step
    new = closed[len(f) :]
    edges = np.linalg.norm(v[new] - v[np.roll(new, 1, axis=1)], axis=2)
    assert edges.max() < 0.009  # across a 3 mm slit and a 4 mm step, plus a grid step


def test_wide_notches_and_straight_borders_are_left_alone() -> None:
    v, f = sheet_with_slit(0.012)
    closed, n = close_border_notches(v, f, max_gap_m=0.006, min_depth_m=0.008)
    assert n == 0 and np.array_equal(closed, f)
