"""Stereo backend of the tracking stage: markers tracked in the left image, matched in the right
image of a rectified pair and triangulated.

Per frame, each left marker's partner is a dot detected in the right image on the same row
(within ``params.stereo_row_band_px``) whose disparity is nearest the marker's disparity in
the previous frame (or, for a marker without one, the median disparity of its nearest matched
neighbours), within ``params.stereo_disparity_jump_px``; the pairing is a one-to-one optimal
assignment. Frame 0 is seeded by labelling the right image's dots with the marker template,
exactly as the left image is labelled. Depth: ``z = f_x B / d`` (``triangulate_rectified``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from physanim.capture.folder_source import _paired, list_frames, read_color
from physanim.capture.stereo import StereoCalibration, StereoRig
from physanim.tracking.assemble import tracks_from_points
from physanim.tracking.detect import detect_markers
from physanim.tracking.label import assign, label_markers
from physanim.tracking.lift import triangulate_rectified
from physanim.tracking.params import TrackParams
from physanim.tracking.track import frontal_template, track_markers_2d
from physanim.tracking.tracks import Tracks


def read_stereo_pairs(
    root: Path,
) -> tuple[list[np.ndarray], list[np.ndarray], StereoCalibration]:
    """Left and right RGB uint8 images T x (H, W, 3) and the calibration of a stereo folder
    (``left/``, ``right/``, ``calibration.yaml``; see ``physanim.capture.folder_source``)."""
    root = Path(root)
    calib = StereoCalibration.load(root / "calibration.yaml")
    lefts, rights = list_frames(root / "left"), list_frames(root / "right")
    idx = _paired(lefts, rights, "right").tolist()
    return [read_color(lefts[n]) for n in idx], [read_color(rights[n]) for n in idx], calib


def _neighbour_disparity(uv: np.ndarray, disparity: np.ndarray, k: int = 4) -> np.ndarray:
    """Disparity (K,) px with gaps filled by the median of the ``k`` nearest known markers'
    disparities (positions ``uv`` (K, 2) px); NaN where no marker has one."""
    known = np.isfinite(disparity) & np.isfinite(uv).all(axis=1)
    want = ~np.isfinite(disparity) & np.isfinite(uv).all(axis=1)
    out = disparity.copy()
    if known.any() and want.any():
        _, nn = cKDTree(uv[known]).query(uv[want], k=min(k, int(known.sum())))
        out[want] = np.median(disparity[known][nn.reshape(int(want.sum()), -1)], axis=1)
    return out


def match_right(
    uv_left: np.ndarray,
    dots_right: np.ndarray,
    disparity_prior: np.ndarray,
    params: TrackParams,
) -> np.ndarray:
    """Right-image partners (K, 2) px of left markers ``uv_left`` (K, 2) px among the dots
    ``dots_right`` (N, 2) px: one-to-one, same row band, disparity nearest ``disparity_prior``
    (K,) px within ``params.stereo_disparity_jump_px``; NaN where unmatched."""
    prior = _neighbour_disparity(uv_left, disparity_prior)
    predicted = uv_left - np.column_stack([prior, np.zeros(len(prior))])
    gate = float(np.hypot(params.stereo_disparity_jump_px, params.stereo_row_band_px))
    match = assign(predicted, dots_right, gate)
    out = np.full_like(uv_left, np.nan)
    ok = match >= 0
    out[ok] = dots_right[match[ok]]
    bad = (
        (np.abs(out[:, 1] - uv_left[:, 1]) > params.stereo_row_band_px)
        | (np.abs(uv_left[:, 0] - out[:, 0] - prior) > params.stereo_disparity_jump_px)
        | ~(uv_left[:, 0] - out[:, 0] > 0)
    )
    out[bad] = np.nan
    return out


def track_markers_stereo(
    lefts: Sequence[np.ndarray],
    rights: Sequence[np.ndarray],
    calib: StereoCalibration,
    template_actor: np.ndarray,
    fps: float,
    params: TrackParams,
    progress: Callable[[int, int], None] | None = None,
) -> Tracks:
    """Track painted markers in a stereo sequence and triangulate them.

    ``lefts``, ``rights`` T x (H, W, 3) uint8 RGB; ``calib`` the pair's calibration (pairs that
    are not already rectified are rectified here; 3D points are then in the rectified left
    camera frame); ``template_actor`` (K, 3) m marker layout on the neutral face; ``fps``
    frames/s. ``Tracks.uv`` are left-image pixels.
    """
    if len(lefts) != len(rights):
        raise ValueError(f"lefts ({len(lefts)}) and rights ({len(rights)}): frame counts differ")
    rig = StereoRig(calib)
    pairs = [rig.rectified(a, b) for a, b in zip(lefts, rights, strict=True)]
    lefts, rights = [a for a, _ in pairs], [b for _, b in pairs]
    template = frontal_template(template_actor)
    uv_l, conf = track_markers_2d(lefts, template, params, progress)
    n_t, k = conf.shape
    uv_r = np.full((n_t, k, 2), np.nan)
    prior = np.full(k, np.nan)
    for t in range(n_t):
        seen = np.isfinite(uv_l[t]).all(axis=1)
        if not seen.any():
            continue
        lo, hi = uv_l[t, seen].min(axis=0), uv_l[t, seen].max(axis=0)
        margin = params.track_gate_px + params.stereo_row_band_px + 10.0
        roi = (lo[0] - params.stereo_max_disparity_px - margin, lo[1] - margin, *(hi + margin))
        dots = detect_markers(rights[t], params, roi=roi)
        if not np.isfinite(prior).any() and len(dots) >= 3:
            match, _ = label_markers(template, dots, params.label_gate_px)
            labelled = np.full((k, 2), np.nan)
            labelled[match >= 0] = dots[match[match >= 0]]
            prior = np.where(seen, uv_l[t, :, 0] - labelled[:, 0], np.nan)
        uv_r[t] = match_right(uv_l[t], dots, prior, params)
        found = np.isfinite(uv_r[t, :, 0])
        prior = np.where(found, uv_l[t, :, 0] - uv_r[t, :, 0], np.nan)
    raw = np.stack(
        [
            triangulate_rectified(uv_l[t], uv_r[t], rig.K, rig.baseline, rig.doffs)
            for t in range(n_t)
        ]
    )
    return tracks_from_points(uv_l, conf, raw, template_actor, fps, params)
