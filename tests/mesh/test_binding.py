"""Closest-point binding (eqs 4.6-4.14) and the kinematic shape-motion model (eqs 4.15-4.16)."""

import numpy as np
import pytest

from physanim.mesh.binding import (
    REGION_EDGE,
    REGION_FACE,
    REGION_VERTEX,
    bind_points,
    closest_points_on_triangles,
)
from physanim.mesh.kinematic import animate_bound_points


def wavy_grid(n: int = 10, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A jittered, wavy (n x n) grid surface 0.1 m across: (V, 3) metres, (F, 3)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 0.1, n), np.linspace(0, 0.1, n))
    z = 0.01 * np.sin(30 * x) * np.cos(20 * y)
    v = np.c_[x.ravel(), y.ravel(), z.ravel()] + rng.normal(0, 0.002, (n * n, 3))
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[:-1, 1:].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
    )
    return v, np.r_[np.c_[a, b, d], np.c_[a, d, c]]


def test_regions_of_a_right_triangle_match_analytic_closest_points():
    a, b, c = np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    p = np.array(
        [
            [0.2, 0.2, 0.5],  # above the face
            [0.5, -0.3, 0.1],  # beyond edge ab
            [-0.5, -0.5, 0.0],  # beyond vertex a
            [2.0, 0.5, 0.0],  # beyond vertex b; the seed's unclamped edge rule would miss it
        ]
    )
    w, d2, region = closest_points_on_triangles(p, a, b, c)
    q = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
    expected = np.array([[0.2, 0.2, 0], [0.5, 0, 0], [0, 0, 0], [1, 0, 0]])
    np.testing.assert_allclose(q, expected, atol=1e-15)
    np.testing.assert_allclose(d2, np.sum((p - expected) ** 2, axis=1), atol=1e-15)
    assert list(region) == [REGION_FACE, REGION_EDGE, REGION_VERTEX, REGION_VERTEX]


def test_binding_matches_brute_force_dense_sampling():
    """The indexed search returns the global minimum: compare with dense sampling of every
    triangle (an independent upper bound, within the sampling resolution)."""
    v, f = wavy_grid(8)
    rng = np.random.default_rng(1)
    p = rng.uniform(-0.02, 0.12, (150, 3))
    b = bind_points(p, v, f, candidates=2)
    s = np.linspace(0, 1, 41)
    u, w = np.meshgrid(s, s)
    keep = u + w <= 1
    bary = np.c_[1 - u[keep] - w[keep], u[keep], w[keep]]  # (S, 3)
    samples = np.einsum("sc,fcd->fsd", bary, v[f]).reshape(-1, 3)
    brute = np.min(np.linalg.norm(p[:, None] - samples[None], axis=2), axis=1)
    assert np.all(b.distance <= brute + 1e-12)
    assert np.max(brute - b.distance) < 1.5e-3  # sample spacing ~ 0.02 m / 40 * sqrt(2)
    np.testing.assert_allclose(np.linalg.norm(p - b.closest, axis=1), b.distance, atol=1e-15)
    assert np.all(b.weights >= -1e-12)
    np.testing.assert_allclose(b.weights.sum(axis=1), 1.0, atol=1e-12)


def test_points_on_the_mesh_reproduce_its_deformation_to_1e_9_m():
    v, f = wavy_grid(10, seed=2)
    rng = np.random.default_rng(3)
    tri = rng.integers(0, len(f), 2000)
    bary = rng.dirichlet(np.ones(3), 2000)
    on_mesh = np.einsum("nc,ncd->nd", bary, v[f[tri]])
    binding = bind_points(on_mesh, v, f)
    assert binding.distance.max() < 1e-12
    # Random smooth + noisy deformation over 5 frames, frame 0 = the rest shape.
    t = np.linspace(0, 1, 5)[:, None, None]
    motion = v[None] + t * (0.01 * np.sin(40 * v[None]) + rng.normal(0, 0.003, (1,) + v.shape))
    out = animate_bound_points(on_mesh, binding, f, motion)
    expected = np.einsum("nc,tncd->tnd", bary, motion[:, f[tri]])
    assert out.shape == (5, 2000, 3)
    assert np.abs(out - expected).max() < 1e-9


def test_off_mesh_points_keep_their_offset_under_translation():
    v, f = wavy_grid(6)
    p = np.array([[0.05, 0.05, 0.03], [0.2, 0.2, 0.0]])
    binding = bind_points(p, v, f)
    shift = np.array([0.01, -0.02, 0.005])
    motion = np.stack([v, v + shift])
    out = animate_bound_points(p, binding, f, motion)
    np.testing.assert_allclose(out[1], p + shift, atol=1e-15)


def test_bad_shapes_raise_clear_errors():
    v, f = wavy_grid(4)
    with pytest.raises(ValueError, match="points must have shape"):
        bind_points(np.zeros((3, 2)), v, f)
    with pytest.raises(ValueError, match="faces index vertices"):
        bind_points(np.zeros((3, 3)), v, f + 100)
