"""Track a recording with the configured backend: painted markers lifted to 3D by the depth or
by triangulating the stereo pair, or the markerless face mesh's landmarks followed by optical
flow; then the checks of ``physanim.tracking.checks``."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from physanim.pipeline import ProgressFn
from physanim.tracking.params import TrackParams
from physanim.tracking.tracks import Tracks


@dataclass(frozen=True)
class TrackedRecording:
    """``tracks`` of the K landmarks ``names`` with neutral positions ``template`` (K, 3) m in
    the actor frame; ``problems``: the checks' warnings (each also warned)."""

    names: list[str]
    template: NDArray
    tracks: Tracks
    problems: list[str]


def track_recording(
    colour: Any,
    depth: Any,
    K: NDArray,
    fps: float,
    params: TrackParams,
    lift: str,
    template: Path,
    stereo_dir: Path,
    progress: ProgressFn | None = None,
) -> TrackedRecording:
    """Track ``colour`` (T, H, W, 3) uint8 with ``depth`` (T, H, W) m (numpy or Zarr, read
    only by the backends that use them) and intrinsics ``K`` (3, 3) px at ``fps`` frames/s.

    ``params.backend`` "markerless": the face mesh's landmarks (``MARKERLESS_POINTS``, their
    neutral positions from the face model); else the markers of the ``template`` file (JSON or
    Zarr), lifted by ``lift`` "depth" or "stereo" (the pair in ``stereo_dir``). Raises
    ``TrackingError`` for tracks with nothing lifted to 3D or a face of the wrong size
    (``check_tracks``)."""
    from physanim.tracking.checks import check_tracks
    from physanim.tracking.template import load_marker_template

    if params.backend == "markerless":
        from physanim.tracking.markerless import (
            MARKERLESS_POINTS,
            landmark_template,
            track_markerless_rgbd,
        )

        names, neutral = list(MARKERLESS_POINTS), landmark_template()
        tracks = track_markerless_rgbd(colour[...], depth[...], K, fps, params, progress)
        what = "the face model"
    else:
        names, neutral = load_marker_template(template)
        what = f"the template {template}"
        if lift == "stereo":
            from physanim.tracking.stereo_track import read_stereo_pairs, track_markers_stereo

            lefts, rights, calib = read_stereo_pairs(stereo_dir)
            tracks = track_markers_stereo(lefts, rights, calib, neutral, fps, params, progress)
        else:
            from physanim.tracking.track import track_markers_rgbd

            frames = (colour[...], depth[...], K)
            tracks = track_markers_rgbd(*frames, neutral, fps, params, progress)
    problems = check_tracks(tracks, neutral, params.backend, what)
    for message in problems:
        warnings.warn(message, UserWarning, stacklevel=2)
    return TrackedRecording(list(names), np.asarray(neutral), tracks, problems)
