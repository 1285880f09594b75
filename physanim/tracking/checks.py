"""Checks of tracked landmarks before anything is fitted to them: something was tracked, and
the tracked face has the size of its template (which exposes a wrong depth scale or wrong
intrinsics, since 3D points scale with both)."""

from __future__ import annotations

import numpy as np

from physanim.tracking.tracks import TrackingError, Tracks
from physanim.transforms import fit_transform

__all__ = ["TrackingError", "check_tracks", "face_scale"]

#: Tracked-face size / template size outside these ranges is refused. Markers: the template is
#: the actor's own layout (ratio 1); markerless: the face model's feature points are about
#: three quarters of an adult's (outer eye corners 62 mm apart), and faces differ.
SCALE_RANGE = {"markers": (0.75, 1.33), "markerless": (0.5, 2.2)}
#: Below this fraction of landmark-frames tracked, the stage warns.
MIN_TRACKED_FRACTION = 0.5
#: Below this fraction of frames with a face found (any landmark tracked), the stage warns.
MIN_FACE_FRAMES = 0.97

SCALE_FIX = (
    "the depth scale or the intrinsics are wrong (RGBD folder: depth_scale in intrinsic.json "
    "is raw units per metre, fx/fy in px of the colour images; stereo: T in metres); run "
    "`physanim check DATASET`"
)


def face_scale(tracks: Tracks, template: np.ndarray) -> float:
    """Median over frames of the similarity scale mapping ``template`` (K, 3) m onto the
    tracked points (T, K, 3) m (confidence-weighted; NaN if no frame has 3 points)."""
    scales = []
    for t in range(len(tracks.points)):
        w = np.where(np.isfinite(tracks.points[t]).all(axis=1), tracks.confidence[t], 0.0)
        if np.count_nonzero(w) < 3:
            continue
        try:
            tr = fit_transform(template, np.nan_to_num(tracks.points[t]), w)
        except ValueError:  # collinear points
            continue
        scales.append(tr.scale)
    return float(np.median(scales)) if scales else float("nan")


def check_tracks(tracks: Tracks, template: np.ndarray, backend: str, what: str) -> list[str]:
    """Raise ``TrackingError`` if no landmark was lifted to 3D or the tracked face is not the
    size of ``template`` (K, 3) m (``SCALE_RANGE[backend]``; ``what`` names the template);
    return warnings (one line each)."""
    seen = tracks.confidence > 0
    n_t = len(seen)
    if not seen.any():
        raise TrackingError(
            f"landmarks were found in the colour images but none has valid depth under it in "
            f"any of the {n_t} frames; the depth is empty or not registered to the colour "
            "camera: run `physanim check DATASET`"
        )
    scale = face_scale(tracks, template)
    lo, hi = SCALE_RANGE[backend]
    if np.isfinite(scale) and not lo <= scale <= hi:
        raise TrackingError(f"the tracked face is {scale:.2f} x the size of {what}: {SCALE_FIX}")
    warnings = []
    faces = int(seen.any(axis=1).sum())
    if faces < MIN_FACE_FRAMES * n_t:
        warnings.append(
            f"a face was found in only {faces} of {n_t} frames ({faces / n_t:.0%}); the frames "
            "without one are filled from their neighbours: check the framing and lighting"
        )
    if seen.mean() < MIN_TRACKED_FRACTION:
        frames = int(seen.any(axis=1).sum())
        warnings.append(
            f"only {seen.mean():.0%} of landmark-frames tracked (a face in {frames} of {n_t} "
            "frames); check the recording's framing and lighting"
        )
    return warnings
