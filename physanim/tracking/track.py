"""Markers backend of the tracking stage: label, track (LK + re-detection), lift, smooth, pose.

Frames are RGB uint8 (H, W, 3) images; pixel coordinates are (u = column, v = row); 3D points
are metres in the colour camera frame (OpenCV axes: +x right, +y down, +z forward).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import cv2
import numpy as np
from scipy.spatial import cKDTree

from physanim.tracking.assemble import tracks_from_depth
from physanim.tracking.detect import detect_markers
from physanim.tracking.label import assign, label_markers
from physanim.tracking.params import TrackParams
from physanim.tracking.tracks import TrackingError, Tracks


def frontal_template(markers_actor: np.ndarray) -> np.ndarray:
    """2D template (K, 2) of actor-frame marker positions (K, 3) m seen from the front.

    A camera in front of the actor (OpenCV axes) sees actor +x to the right and actor +y up,
    so the template is (x, -y); only its shape matters (labelling fits a similarity).
    """
    return np.column_stack([markers_actor[:, 0], -markers_actor[:, 1]])


def _gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def track_markers_2d(
    frames: Sequence[np.ndarray],
    template: np.ndarray,
    params: TrackParams,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Label dots at frame 0 with the 2D ``template`` (K, 2) and track them through ``frames``.

    Each frame: pyramidal Lucas-Kanade predicts every marker from the previous frame, then
    the detected dots are assigned optimally to the predictions within
    ``params.track_gate_px``. A marker with no dot is reported lost (NaN, confidence 0); its
    internal estimate follows its nearest tracked neighbours so it is re-acquired when it
    reappears.
    Returns ``uv`` (T, K, 2) px and ``confidence`` (T, K).
    """
    n_t, k = len(frames), len(template)
    uv = np.full((n_t, k, 2), np.nan)
    conf = np.zeros((n_t, k))
    dots = detect_markers(frames[0], params)
    if len(dots) < 3:
        raise TrackingError(
            f"frame 0: {len(dots)} painted marker dot(s) found, labelling needs at least 3 of "
            f"the template's {k}; for a recording without painted markers set "
            "track.backend=markerless, else adjust track.marker_rgb / track.chroma_tolerance"
        )
    try:
        match, _ = label_markers(template, dots, params.label_gate_px)
    except ValueError:
        raise TrackingError(
            f"frame 0: cannot fit the marker template ({k} markers) to the {len(dots)} dots "
            "found; for a recording without painted markers set track.backend=markerless, else "
            "check track.template and track.marker_rgb"
        ) from None
    estimate = np.full((k, 2), np.nan)
    estimate[match >= 0] = dots[match[match >= 0]]
    lk = dict(
        winSize=(params.lk_window_px, params.lk_window_px),
        maxLevel=params.lk_levels,
        criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01),
    )
    prev = _gray(frames[0])
    for t in range(1, n_t + 1):
        seen = match >= 0
        estimate[seen] = dots[match[seen]]
        uv[t - 1, seen] = estimate[seen]
        conf[t - 1, seen] = 1.0
        if progress is not None:
            progress(t, n_t)
        if t == n_t:
            break
        cur = _gray(frames[t])
        before = estimate.copy()
        known = np.isfinite(before).all(axis=1)
        p0 = before[known].astype(np.float32).reshape(-1, 1, 2)
        p1, status, _ = cv2.calcOpticalFlowPyrLK(prev, cur, p0, None, **lk)
        ok = np.zeros(k, dtype=bool)
        ok[known] = status.ravel() == 1
        predicted = np.full((k, 2), np.nan)
        predicted[ok] = p1.reshape(-1, 2)[status.ravel() == 1]
        predicted[~seen] = np.nan  # LK on a vanished dot follows the skin, not the dot
        margin = 3.0 * params.track_gate_px + 10.0
        lo, hi = before[known].min(axis=0) - margin, before[known].max(axis=0) + margin
        dots = detect_markers(frames[t], params, roi=(*np.floor(lo), *np.ceil(hi)))
        match = assign(predicted, dots, params.track_gate_px)
        # Second pass: markers without a match move with their matched neighbours.
        rest = known & (match < 0)
        if rest.any():
            found = np.full((k, 2), np.nan)
            found[match >= 0] = dots[match[match >= 0]]
            estimate[rest] = _follow_neighbours(before, found, match >= 0, rest)
            free = np.setdiff1d(np.arange(len(dots)), match[match >= 0])
            again = assign(estimate[rest], dots[free], params.track_gate_px)
            sub = np.full(int(rest.sum()), -1)
            sub[again >= 0] = free[again[again >= 0]]
            match[rest] = sub
        prev = cur
    return uv, conf


def _follow_neighbours(
    before: np.ndarray, after: np.ndarray, reliable: np.ndarray, targets: np.ndarray, k: int = 4
) -> np.ndarray:
    """Positions (M, 2) px of the ``targets`` (K,) bool markers moved from ``before`` (K, 2) by
    the mean motion ``after - before`` of their ``k`` nearest ``reliable`` (K,) bool markers."""
    if not reliable.any():
        return before[targets]
    motion = after[reliable] - before[reliable]
    _, nn = cKDTree(before[reliable]).query(before[targets], k=min(k, int(reliable.sum())))
    return before[targets] + motion[nn.reshape(int(targets.sum()), -1)].mean(axis=1)


def track_markers_rgbd(
    colors: Sequence[np.ndarray],
    depths: Sequence[np.ndarray],
    K: np.ndarray,
    template_actor: np.ndarray,
    fps: float,
    params: TrackParams,
    progress: Callable[[int, int], None] | None = None,
) -> Tracks:
    """Track painted markers in an RGB-D sequence and lift them to 3D.

    ``colors`` T x (H, W, 3) uint8 RGB, ``depths`` T x (H, W) m (0 / NaN invalid), ``K`` (3, 3)
    colour intrinsics (depth registered to colour), ``template_actor`` (K, 3) m marker layout
    on the neutral face in the actor frame, ``fps`` frames/s.
    """
    if len(colors) != len(depths):
        raise ValueError(f"colors ({len(colors)}) and depths ({len(depths)}): frame counts differ")
    uv, conf = track_markers_2d(colors, frontal_template(template_actor), params, progress)
    return tracks_from_depth(uv, conf, depths, K, template_actor, fps, params)
