"""Stage ``track``: landmarks tracked in the colour frames (painted markers or markerless) in 3D."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import ConfigDict, Field

from physanim.pipeline import DatasetParams, StageContext, StageSpec
from physanim.tracking.params import TrackParams
from tasks.ingest import IngestOutput


class TrackStageParams(TrackParams):
    """Tracking settings, the marker template and how markers are lifted to 3D."""

    model_config = ConfigDict(extra="forbid")
    template: str = Field(
        "ground_truth.zarr", description="marker template: JSON or Zarr, relative to the dataset"
    )
    lift: Literal["depth", "stereo"] = Field(
        "depth", description="3D from the ingested depth, or by triangulating the stereo pair"
    )
    stereo_dir: str = Field("stereo", description="stereo pair folder, relative to the dataset")


@dataclass(frozen=True)
class TrackOutput:
    """K landmarks tracked over T frames (``physanim.tracking.track.Tracks`` plus what they are).

    ``uv`` (T, K, 2) px and ``points`` (T, K, 3) m camera frame, NaN where unobserved;
    ``confidence`` (T, K) in [0, 1]; ``head_pose`` (T, 4, 4) camera <- actor, m;
    ``template`` (K, 3) m neutral landmark positions in the actor frame; ``landmark_names``
    (K) (stored as ``names``); ``fps`` frames/s of the capture; ``backend``, ``lift``.
    """

    uv: np.ndarray
    points: np.ndarray
    confidence: np.ndarray
    head_pose: np.ndarray
    template: np.ndarray
    landmark_names: list[str] = field(metadata={"stored": "names"})
    fps: float
    backend: str
    lift: str


def fingerprint(dataset: DatasetParams, params: TrackStageParams) -> Mapping[str, object]:
    """Content hash of the marker template (names and neutral positions); with
    ``lift: stereo``, size and modification time of every file of the stereo pair."""
    from physanim.store import files_fingerprint
    from physanim.tracking.template import load_marker_template

    out: dict[str, object] = {}
    if params.lift == "stereo" and params.backend != "markerless":
        stereo = dataset.path / params.stereo_dir
        files = [p for p in stereo.rglob("*") if p.is_file()] if stereo.is_dir() else []
        out["stereo"] = files_fingerprint(files, dataset.path)
    if params.backend == "markerless":
        return {"template": "face model", **out}
    path = dataset.path / params.template
    if not path.exists():
        return {"template": "missing", **out}
    names, pos = load_marker_template(path)
    digest = hashlib.sha256(("|".join(names)).encode() + pos.tobytes()).hexdigest()
    return {"template": digest, **out}


def compute(
    params: TrackStageParams, ingest: IngestOutput, ctx: StageContext[TrackStageParams]
) -> TrackOutput:
    """uv (T,K,2) px, points (T,K,3) m camera frame, confidence (T,K), head_pose (T,4,4).

    Refuses tracks with nothing lifted to 3D or a face of the wrong size (``check_tracks``);
    its warnings go to the summary."""
    import warnings

    from physanim.face.landmarks import FEATURE_POINTS
    from physanim.tracking.checks import check_tracks
    from physanim.tracking.template import load_marker_template

    tracking = TrackParams.model_validate(
        params.model_dump(exclude={"template", "lift", "stereo_dir"})
    )
    fps = float(ingest.fps)
    progress = ctx.progress("track")
    if params.backend == "markerless":
        from physanim.tracking.markerless import feature_template, track_markerless_rgbd

        names, template = list(FEATURE_POINTS), feature_template()
        frames = (ingest.color[...], ingest.depth[...], ingest.K)
        tracks = track_markerless_rgbd(*frames, fps, tracking, progress)
    elif params.lift == "stereo":
        from physanim.tracking.stereo_track import read_stereo_pairs, track_markers_stereo

        names, template = load_marker_template(ctx.dataset_dir / params.template)
        lefts, rights, calib = read_stereo_pairs(ctx.dataset_dir / params.stereo_dir)
        tracks = track_markers_stereo(lefts, rights, calib, template, fps, tracking, progress)
    else:
        from physanim.tracking.track import track_markers_rgbd

        names, template = load_marker_template(ctx.dataset_dir / params.template)
        frames = (ingest.color[...], ingest.depth[...], ingest.K)
        tracks = track_markers_rgbd(*frames, template, fps, tracking, progress)
    what = "the face model" if params.backend == "markerless" else f"the template {params.template}"
    problems = check_tracks(tracks, template, params.backend, what)
    for message in problems:
        warnings.warn(message, UserWarning, stacklevel=1)
    seen = tracks.confidence > 0
    ctx.summary.update(
        markers=len(names), tracked_fraction=round(float(seen.mean()), 4), warnings=problems
    )
    return TrackOutput(
        tracks.uv, tracks.points, tracks.confidence, tracks.head_pose, template, list(names),
        fps, params.backend, params.lift,
    )  # fmt: skip


SPEC = StageSpec.typed(
    "track",
    compute,
    version="2",
    doc="markers (or markerless face mesh) tracked in 2D, lifted to 3D (depth/stereo), smoothed",
    fingerprint=fingerprint,
)
