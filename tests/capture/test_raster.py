"""The z-buffer rasteriser against analytic answers: depth along each pixel's ray on a tilted
plane, perspective-correct barycentrics, occlusion, and the first of equal-depth triangles."""

from __future__ import annotations

import numpy as np

from physanim.capture import raster
from physanim.capture.raster import rasterize
from physanim.warm import warm_rasterizer

K = np.array([[200.0, 0.0, 32.0], [0.0, 200.0, 24.0], [0.0, 0.0, 1.0]])
SIZE = (48, 64)


def _plane(z0: float, slope: float, half: float) -> np.ndarray:
    """Corners (4, 3) m of the square |x|, |y| <= half * z on the plane z = z0 + slope x
    (choose ``half`` so that its edges fall between pixel centres)."""
    corners = []
    for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        z = z0 / (1.0 - slope * sx * half)  # the corner on the ray (sx half, sy half, 1)
        corners.append([sx * half * z, sy * half * z, z])
    return np.array(corners)


def test_depth_and_barycentrics_follow_each_pixel_ray_on_a_tilted_plane() -> None:
    v = _plane(1.0, 0.5, 0.1025)
    ras = rasterize(v, np.array([[0, 1, 2], [0, 2, 3]]), K, SIZE)
    rows, cols = np.nonzero(ras.mask)
    x, y = (cols - K[0, 2]) / K[0, 0], (rows - K[1, 2]) / K[1, 1]  # the rays (x, y, 1)
    # the square spans |x|, |y| <= 0.1025 on the rays: 41 x 41 pixel centres (u, v = c +- 20)
    assert len(rows) == 41 * 41 and np.abs(x).max() <= 0.1
    np.testing.assert_allclose(ras.depth[rows, cols], 1.0 / (1.0 - 0.5 * x), rtol=1e-12)
    # perspective-correct weights interpolate the 3D point on the ray, not a screen average
    p = ras.interpolate(v, np.array([[0, 1, 2], [0, 2, 3]]))
    z = ras.depth[rows, cols]
    np.testing.assert_allclose(p, np.stack([x * z, y * z, z], axis=1), atol=1e-12)
    assert np.isnan(ras.depth[~ras.mask]).all() and (ras.face[~ras.mask] == -1).all()


def test_nearer_triangle_hides_farther_and_equal_depth_keeps_the_first() -> None:
    far, near = _plane(2.0, 0.0, 0.1025), _plane(1.0, 0.0, 0.0525)
    v = np.vstack([far, near, near])  # faces 2-3: the near square; 4-5: an exact copy
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10], [8, 10, 11]])
    ras = rasterize(v, faces, K, SIZE)
    front = np.isin(ras.face, [2, 3])
    assert front.sum() == 21 * 21 and not np.isin(ras.face, [4, 5]).any()
    np.testing.assert_allclose(ras.depth[front], 1.0, rtol=1e-12)
    np.testing.assert_allclose(ras.depth[ras.mask & ~front], 2.0, rtol=1e-12)
    assert ras.mask.sum() == 41 * 41


def test_triangles_behind_the_near_plane_are_skipped() -> None:
    v = _plane(0.04, 0.0, 0.1)  # closer than the default near = 0.05 m
    assert not rasterize(v, np.array([[0, 1, 2], [0, 2, 3]]), K, SIZE).mask.any()


def test_warm_up_compiles_the_z_buffer() -> None:
    warm_rasterizer()
    assert raster._zbuffer.signatures  # compiled (or loaded from numba's cache) in this process
