"""Weighted least-squares similarity / rigid transforms in 2D or 3D (Umeyama 1991).

The one home of the rigid / similarity-transform helpers shared by tracking, face and mesh
(bottom layer of the library: imports numpy only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Transform:
    """x' = scale * x @ rotation.T + translation; ``rotation`` (d, d), ``translation`` (d,)."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Transform points (..., d)."""
        return self.scale * np.asarray(x) @ self.rotation.T + self.translation


def fit_transform(
    source: np.ndarray,
    target: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    with_scale: bool = True,
) -> Transform:
    """Weighted least-squares transform mapping ``source`` (K, d) onto ``target`` (K, d).

    ``weights`` (K,) >= 0 (default 1); points with zero weight are ignored. Needs at least
    ``d`` points of positive weight that are not collinear; raises ValueError otherwise.
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if source.shape != target.shape or source.ndim != 2:
        raise ValueError(f"source {source.shape} and target {target.shape}: need equal (K, d)")
    w = np.ones(len(source)) if weights is None else np.asarray(weights, dtype=np.float64)
    d = source.shape[1]
    if np.count_nonzero(w > 0) < d:
        raise ValueError(f"need at least {d} points with positive weight, got {np.sum(w > 0)}")
    w = w / w.sum()
    mu_s, mu_t = w @ source, w @ target
    xs, xt = source - mu_s, target - mu_t
    cov = (xt * w[:, None]).T @ xs
    u, sig, vt = np.linalg.svd(cov)
    if sig[d - 2] <= 1e-12 * max(sig[0], 1e-300):
        raise ValueError("points are collinear or coincident; the transform is undetermined")
    s = np.ones(d)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[-1] = -1.0
    rot = (u * s) @ vt
    scale = float(np.sum(sig * s) / np.sum(w * np.sum(xs**2, axis=1))) if with_scale else 1.0
    return Transform(scale=scale, rotation=rot, translation=mu_t - scale * rot @ mu_s)


def rotation_angle_deg(rotation: np.ndarray) -> float:
    """The angle (degrees) by which the rotation matrix ``rotation`` (3, 3) turns."""
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))))


def cross_matrices(v: np.ndarray) -> np.ndarray:
    """(n, 3, 3) matrices [v]x with [v]x u = v x u, of vectors ``v`` (n, 3). A small rotation
    omega moves a point p by omega x p = -[p]x omega: -[p]x is the rotation's Jacobian."""
    v = np.asarray(v)
    z = np.zeros(len(v), dtype=v.dtype)
    return np.stack(
        [
            np.stack([z, -v[:, 2], v[:, 1]], axis=1),
            np.stack([v[:, 2], z, -v[:, 0]], axis=1),
            np.stack([-v[:, 1], v[:, 0], z], axis=1),
        ],
        axis=1,
    )
