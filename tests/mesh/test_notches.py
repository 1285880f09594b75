"""Zipping border notches (scanner slits) of a surface shut."""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from physanim.mesh.notches import border_loops, close_border_notches, fair_zips
from physanim.mesh.topology import boundary_vertex_mask, watertight_problems


def sheet_with_slit(width_m: float, depth_m: float = 0.02, fade: bool = False):
    """A 6 x 6 cm grid sheet with a slit of ``width_m`` cut up from its bottom border,
    ``depth_m`` long, its two sides at different depths (z) like a crease: a 4 mm step, cut
    off at the slit's tip or (``fade``) falling linearly to nothing there."""
    xs, ys = np.linspace(-0.03, 0.03, 61), np.linspace(-0.03, 0.03, 61)
    g = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    faces = Delaunay(g).simplices
    centroids = g[faces].mean(axis=1)
    slit = (np.abs(centroids[:, 0]) < width_m / 2) & (centroids[:, 1] < -0.03 + depth_m)
    faces = faces[~slit]
    used, faces = np.unique(faces, return_inverse=True)
    faces = faces.reshape(-1, 3)
    g = g[used]
    tip = -0.03 + depth_m
    z = np.where(g[:, 0] > 0, -0.004, 0.0) * (g[:, 1] < tip)  # a 4 mm step
    if fade:
        z = np.where(g[:, 0] > 0, -0.004, 0.0) * np.clip((tip - g[:, 1]) / depth_m, 0.0, 1.0)
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


def test_fairing_turns_the_zipped_step_into_a_ramp_and_holds_the_rest() -> None:
    """The zip across the 4 mm step is a wall (a face turned more than 60 degrees from the
    sheet); faired over 6 mm it is a ramp (every face more than 1 mm from the bottom border
    within 35 degrees, measured 29.7; the first row at the slit's mouth stays steep, its
    outline held); the vertices
    farther than 6 mm from the zip have not moved at all, those on the open border only in
    depth (the outline stays)."""
    v, f = sheet_with_slit(0.003, fade=True)
    closed, _ = close_border_notches(v, f, max_gap_m=0.006, min_depth_m=0.008)
    zipped = np.arange(len(closed)) >= len(f)

    def tilt(points: np.ndarray) -> np.ndarray:
        n = np.cross(points[closed[:, 1]] - points[closed[:, 0]],
                     points[closed[:, 2]] - points[closed[:, 0]])  # fmt: skip
        return np.degrees(np.arccos(np.abs(n[:, 2]) / np.linalg.norm(n, axis=1)))

    faired = fair_zips(v, closed, zipped, 0.006)
    inner = faired[closed].mean(axis=1)[:, 1] > -0.029
    before, after = tilt(v)[inner].max(), tilt(faired)[inner].max()
    assert before > 60.0 and after < 35.0, (before, after)
    seeds = np.unique(closed[zipped])
    far = np.linalg.norm(v[:, None, :2] - v[seeds][None, :, :2], axis=2).min(axis=1) > 0.0061
    np.testing.assert_array_equal(faired[far], v[far])
    border = boundary_vertex_mask(closed, len(v))
    np.testing.assert_array_equal(faired[border, :2], v[border, :2])
    assert np.array_equal(fair_zips(v, closed, zipped, 0.0), v)
