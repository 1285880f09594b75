"""The truth comparison's fast closest-point search (Open3D's BVH) gives the reference's (the
seed's exact grid search) figures: surface distances, followed true motion and fidelity."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from physanim.evaluate.fidelity import follow_truth, motion_fidelity
from physanim.evaluate.measures import surface_errors
from physanim.mesh.binding import REGION_FACE, REGION_VERTEX, bind_points, bind_points_bvh


def bumpy_surface(n_frames: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """A curved sheet (10 cm, 2 mm cells) around (0.1, 0.2, 0.3) m that bulges over time:
    (T, V, 3) m, faces (F, 3)."""
    g = np.stack(np.meshgrid(np.linspace(-0.05, 0.05, 51), np.linspace(-0.05, 0.05, 51)), -1)
    xy = g.reshape(-1, 2)
    f = Delaunay(xy).simplices
    bump = np.exp(-(xy**2).sum(axis=1) / 6e-4)
    frames = []
    for a in np.linspace(0.0, 0.01, n_frames):
        z = 0.004 * np.sin(60 * xy[:, 0]) * np.cos(40 * xy[:, 1]) + a * bump
        frames.append(np.c_[xy, z] + np.array([0.1, 0.2, 0.3]))
    return np.stack(frames), f


def test_bvh_binding_matches_the_exact_search() -> None:
    tv, tf = bumpy_surface()
    rng = np.random.default_rng(1)
    pts = tv[0][rng.choice(tv.shape[1], 600, False)] + rng.normal(0, 0.003, (600, 3))
    corners = tv[0][tf[:3]].mean(axis=1)  # on faces, plus exact vertices
    pts = np.r_[pts, corners, tv[0][:5]]
    fast = bind_points_bvh(pts, tv[0], tf)
    np.testing.assert_allclose(fast.weights.sum(axis=1), 1.0)
    recomputed = np.einsum("nc,ncd->nd", fast.weights, tv[0][tf[fast.triangle]])
    np.testing.assert_allclose(fast.closest, recomputed, atol=1e-12)
    assert set(fast.region[-8:-5]) == {REGION_FACE} and set(fast.region[-5:]) == {REGION_VERTEX}
    exact = bind_points(pts, tv[0], tf)
    np.testing.assert_allclose(fast.distance, exact.distance, atol=1e-7)
    assert np.mean(fast.region == exact.region) > 0.95  # ties at shared edges may differ
    moving = np.broadcast_to(pts, (len(tv), *pts.shape))
    err = surface_errors([moving], tv, tf, range(len(tv)), "grid")[0]
    fast_err = surface_errors([moving], tv, tf, range(len(tv)), "bvh")[0]
    np.testing.assert_allclose(fast_err, err, rtol=1e-5)


@pytest.mark.parametrize("scale", [0.0, 0.6])
def test_bvh_follows_the_truth_like_the_exact_search(scale: float) -> None:
    tv, tf = bumpy_surface()
    rng = np.random.default_rng(2)
    pts = tv[0][rng.choice(tv.shape[1], 800, False)] + rng.normal(0, 0.002, (800, 3))
    ref = follow_truth(pts, tv, tf, "grid")
    fast = follow_truth(pts, tv, tf, "bvh")
    np.testing.assert_allclose(fast.distance, ref.distance, atol=1e-7)
    np.testing.assert_allclose(fast.displacement, ref.displacement, atol=1e-7)
    labels = rng.integers(0, 5, len(pts))
    model = scale * ref.displacement + rng.normal(0, 1e-4, ref.displacement.shape)
    a = motion_fidelity(model, ref.displacement, labels)
    b = motion_fidelity(model, fast.displacement, labels)
    np.testing.assert_allclose(b.overall[1:], a.overall[1:], rtol=0.01)
    np.testing.assert_allclose(b.regions[1:], a.regions[1:], rtol=0.01)
