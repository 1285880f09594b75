"""Tracked landmarks and their post-processing: temporal smoothing and head poses.

Shared by the tracking backends (markers, markerless, stereo) and ``assemble``; 3D points
are metres in the colour camera frame (OpenCV axes: +x right, +y down, +z forward).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from physanim.tracking.params import TrackParams
from physanim.tracking.smooth import kalman_rts, one_euro
from physanim.transforms import cross_matrices, fit_transform


class TrackingError(ValueError):
    """Tracking found nothing usable; the message names the cause and the fix."""


@dataclass(frozen=True)
class Tracks:
    """Tracked landmarks over T frames and K landmarks.

    ``uv`` (T, K, 2) px and ``points`` (T, K, 3) m (camera frame) are NaN where a landmark
    was not observed; ``confidence`` (T, K) in [0, 1] (0 = lost); ``head_pose`` (T, 4, 4)
    camera <- actor rigid transform (m) fitted to the observed landmarks.
    """

    uv: np.ndarray
    points: np.ndarray
    confidence: np.ndarray
    head_pose: np.ndarray


def smooth_tracks(points: np.ndarray, fps: float, params: TrackParams) -> np.ndarray:
    """Apply the configured temporal filter to tracks (T, K, 3) m (NaN gaps stay NaN)."""
    if params.smoothing == "one_euro":
        return one_euro(points, fps, params.one_euro_min_cutoff, params.one_euro_beta)
    if params.smoothing == "kalman":
        return kalman_rts(points, fps, params.kalman_accel_std, params.kalman_meas_std)
    return points.copy()


def _frame_poses(
    points: np.ndarray, confidence: np.ndarray, template_actor: np.ndarray, iterations: int
) -> np.ndarray:
    """Per-frame weighted Kabsch with Cauchy reweighting (see :func:`head_poses`)."""
    out = np.full((len(points), 4, 4), np.nan)
    for t in range(len(points)):
        w = np.where(np.isfinite(points[t]).all(axis=1), confidence[t], 0.0)
        if np.count_nonzero(w) < 3:
            continue
        target = np.nan_to_num(points[t])
        weights = w.copy()
        for _ in range(iterations):
            tr = fit_transform(template_actor, target, weights, with_scale=False)
            res = np.linalg.norm(tr.apply(template_actor) - target, axis=1)
            scale = np.median(res[w > 0]) + 1e-6
            weights = w / (1.0 + (res / scale) ** 2)
        out[t] = np.eye(4)
        out[t, :3, :3], out[t, :3, 3] = tr.rotation, tr.translation
    return out


def rigidity_weights(points: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """How rigidly each landmark rides with the head: (K,) in (0, 1].

    ``points`` (T, K, 3) m camera frame, ``poses`` (T, 4, 4) camera <- actor.  A landmark's
    non-rigid motion m_k is the RMS distance, in the head frame, of its positions from their
    median over the sequence; weight 1 / (1 + (m_k / median(m))^2).
    """
    stab = np.einsum("tji,tkj->tki", poses[:, :3, :3], points - poses[:, None, :3, 3])
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        # a point never observed (dense capture: a seen vertex the flow always loses) has no
        # median: NaN, left out below
        warnings.filterwarnings("ignore", "All-NaN slice", RuntimeWarning)
        spread = ((stab - np.nanmedian(stab, axis=0)) ** 2).sum(axis=2)
    ok = np.isfinite(spread)
    m = np.sqrt(np.where(ok, spread, 0.0).sum(axis=0) / np.maximum(ok.sum(axis=0), 1))
    scale = float(np.median(m[ok.any(axis=0)])) if ok.any() else 0.0
    return 1.0 / (1.0 + (m / max(scale, 1e-9)) ** 2)


def head_poses(
    points: np.ndarray, confidence: np.ndarray, template_actor: np.ndarray, iterations: int = 3
) -> np.ndarray:
    """Per-frame camera <- actor rigid transforms (T, 4, 4) from tracks (T, K, 3) m.

    Weighted Kabsch of the actor-frame template (K, 3) m onto each frame's observed points,
    in two passes.  Within a frame, points moving with the expression are down-weighted
    (Cauchy weights on the residual, scale = median residual); between the passes, each
    landmark is weighted by how rigidly it rode with the head over the whole sequence
    (:func:`rigidity_weights`), so the mouth and chin do not drag the pose while they move
    together (on the demo's smile this halved the head-frame error of the moving landmarks:
    relative error 0.32 -> 0.17).  Frames with fewer than 3 observed points give NaN.
    """
    first = _frame_poses(points, confidence, template_actor, iterations)
    seen = np.isfinite(first[:, 0, 0])
    if seen.sum() < 2:
        return first
    rho = rigidity_weights(points[seen], first[seen])
    return _frame_poses(points, confidence * rho[None], template_actor, iterations)


def refine_poses_anisotropic(
    points: np.ndarray,
    confidence: np.ndarray,
    template_actor: np.ndarray,
    poses: np.ndarray,
    axis_weights: tuple[float, float, float],
    iterations: int = 6,
) -> np.ndarray:
    """The poses (T, 4, 4) camera <- actor refined so that each frame's residuals are
    measured with ``axis_weights`` on the camera frame's x, y, z (a lifted point's depth is
    noisier than its image position: a weight below 1 on z trusts the image more).

    Starting from ``poses`` (e.g. :func:`head_poses`), per frame ``iterations`` Gauss-Newton
    steps of min sum_i w_i sum_a c_a e_ia^2, e_i = R X_i + t - P_i, on the rotation (as a
    rotation vector) and translation, with w_i the point's ``confidence`` (T, K) times its
    rigidity under the starting poses (:func:`rigidity_weights`) times Cauchy weights on the
    weighted residual (scale its median). ``points`` (T, K, 3) m camera frame (NaN not
    observed), ``template_actor`` (K, 3) m. Frames whose pose is NaN stay NaN."""
    weights_axis = np.asarray(axis_weights, dtype=np.float64)
    out = poses.copy()
    seen = np.isfinite(poses[:, 0, 0])
    if seen.sum() < 2:
        return out
    rho = rigidity_weights(points[seen], poses[seen])
    eye = np.broadcast_to(np.eye(3), (len(template_actor), 3, 3))
    for t in np.flatnonzero(seen):
        observed = np.isfinite(points[t]).all(axis=1)
        base = np.where(observed, confidence[t], 0.0) * rho
        if np.count_nonzero(base) < 3:
            continue
        target = np.nan_to_num(points[t])
        R, tr = poses[t, :3, :3].copy(), poses[t, :3, 3].copy()
        for _ in range(iterations):
            rx = template_actor @ R.T
            e = rx + tr - target
            res = np.sqrt((e**2 * weights_axis).sum(axis=1))
            w = base / (1.0 + (res / (np.median(res[base > 0]) + 1e-9)) ** 2)
            J = np.concatenate([-cross_matrices(rx), eye], axis=2)  # (K, 3, 6): d e / d (omega, t)
            JW = J * (weights_axis[None, :, None] * w[:, None, None])
            H = np.einsum("kai,kaj->ij", JW, J)
            step = -np.linalg.solve(H + 1e-12 * np.eye(6), np.einsum("kai,ka->i", JW, e))
            R = Rotation.from_rotvec(step[:3]).as_matrix() @ R
            tr = tr + step[3:]
        out[t, :3, :3], out[t, :3, 3] = R, tr
    return out
