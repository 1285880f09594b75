"""Assemble ``Tracks`` from 2D landmark tracks: lift to 3D, smooth, flag unlifted, head pose."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physanim.tracking.lift import lift_depth
from physanim.tracking.params import TrackParams
from physanim.tracking.tracks import Tracks, head_poses, smooth_tracks


def tracks_from_points(
    uv: np.ndarray,
    confidence: np.ndarray,
    raw: np.ndarray,
    template_actor: np.ndarray,
    fps: float,
    params: TrackParams,
) -> Tracks:
    """``Tracks`` from 2D tracks ``uv`` (T, K, 2) px, ``confidence`` (T, K) and unsmoothed 3D
    points ``raw`` (T, K, 3) m (NaN where not lifted): confidence drops to 0 where ``raw`` is
    NaN, points are smoothed (``params.smoothing``) and the head pose is fitted to
    ``template_actor`` (K, 3) m."""
    conf = np.where(np.isfinite(raw).all(axis=2), confidence, 0.0)
    points = smooth_tracks(raw, fps, params)
    uv = np.where(conf[..., None] > 0, uv, np.nan)
    return Tracks(
        uv=uv, points=points, confidence=conf, head_pose=head_poses(points, conf, template_actor)
    )


def tracks_from_depth(
    uv: np.ndarray,
    confidence: np.ndarray,
    depths: Sequence[np.ndarray],
    K: np.ndarray,
    template_actor: np.ndarray,
    fps: float,
    params: TrackParams,
) -> Tracks:
    """``Tracks`` from 2D tracks (T, K, 2) px lifted on depth images T x (H, W) m with colour
    intrinsics ``K`` (3, 3) (robust window median, ``params.depth_window_px``)."""
    raw = np.stack(
        [lift_depth(uv[t], depths[t], K, params.depth_window_px) for t in range(len(uv))]
    )
    return tracks_from_points(uv, confidence, raw, template_actor, fps, params)
