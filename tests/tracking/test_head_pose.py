"""The head pose re-estimated from dense points, refined with depth weighted less than the
image position (``physanim.tracking.tracks.refine_poses_anisotropic``)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from physanim.tracking.tracks import head_poses, refine_poses_anisotropic


def _rotation_error_deg(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Angle (T,) degrees between the rotations of two pose sequences (T, 4, 4)."""
    d = np.einsum("tji,tjk->tik", estimated[:, :3, :3], truth[:, :3, :3])
    return np.degrees(np.arccos(np.clip((np.trace(d, axis1=1, axis2=2) - 1) / 2, -1, 1)))


def _face(n: int, T: int, seed: int = 7) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A face-like shell (n, 3) m (16 x 20 cm, 5 cm relief), its true poses (T, 4, 4) camera
    <- actor (turning by up to 3 degrees, facing the camera at 0.5 m) and its points (T, n, 3)
    camera frame, noise-free."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-0.08, 0.08, n), rng.uniform(-0.1, 0.1, n)
    template = np.c_[x, y, -0.05 * np.cos(x / 0.1) * np.cos(y / 0.12)]
    t = np.arange(T)
    angles = np.c_[2.0 * np.sin(t / 9.0), 3.0 * np.sin(t / 13.0), 0.5 * np.sin(t / 7.0)]
    facing = Rotation.from_euler("x", 180, degrees=True)  # OpenCV: +z away from the camera
    truth = np.tile(np.eye(4), (T, 1, 1))
    truth[:, :3, :3] = (Rotation.from_euler("xyz", angles, degrees=True) * facing).as_matrix()
    truth[:, :3, 3] = [0.0, 0.0, 0.5]
    points = np.einsum("tij,kj->tki", truth[:, :3, :3], template) + truth[:, None, :3, 3]
    return template, truth, points


def test_the_refinement_recovers_exact_poses_from_a_perturbed_start() -> None:
    template, truth, points = _face(500, 10)
    start = truth.copy()
    kick = Rotation.from_euler("xyz", [0.5, -0.4, 0.3], degrees=True).as_matrix()
    start[:, :3, :3] = kick @ truth[:, :3, :3]
    start[:, :3, 3] += [0.002, -0.001, 0.003]
    start[3] = np.nan  # a frame without a pose stays without
    refined = refine_poses_anisotropic(points, np.ones((10, 500)), template, start, (1, 1, 0.1))
    ok = np.arange(10) != 3
    assert np.isnan(refined[3]).all()
    np.testing.assert_allclose(refined[ok], truth[ok], atol=1e-9)


def test_depth_weighted_less_gives_a_truer_pose_when_depth_is_noisier() -> None:
    """Image-plane noise 0.1 mm, depth noise 1.5 mm (lifted points: flow against the depth
    sensor): weighting depth 0.1 brings the pose closer to the truth than counting it in
    full (measured: mean error 0.053 -> 0.043 degrees). The gain is modest because a turn
    about an image axis moves a face mostly in depth; on the captured performances the
    weight matters where depth is also biased (a bulge towards the camera)."""
    template, truth, points = _face(3000, 30)
    rng = np.random.default_rng(3)
    noisy = points + rng.normal(size=points.shape) * [1e-4, 1e-4, 1.5e-3]
    confidence = np.ones(noisy.shape[:2])
    start = head_poses(noisy, confidence, template)
    full = _rotation_error_deg(
        refine_poses_anisotropic(noisy, confidence, template, start, (1, 1, 1)), truth
    )
    weighted = _rotation_error_deg(
        refine_poses_anisotropic(noisy, confidence, template, start, (1, 1, 0.1)), truth
    )
    print(f"mean rotation error: depth in full {full.mean():.4f}, weighted {weighted.mean():.4f}")
    assert weighted.mean() < 0.9 * full.mean()
