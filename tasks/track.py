"""Stage ``track``: landmarks tracked in the colour frames (painted markers or markerless) in 3D."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import ConfigDict, Field

from physanim.pipeline import DatasetParams, StageContext, StageOutput, StageSpec
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
class TrackOutput(StageOutput):
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
    from physanim.tracking.recording import track_recording

    tracking = TrackParams.model_validate(
        params.model_dump(exclude={"template", "lift", "stereo_dir"})
    )
    found = track_recording(
        ingest.color, ingest.depth, ingest.K, float(ingest.fps), tracking, params.lift,
        ctx.dataset_dir / params.template, ctx.dataset_dir / params.stereo_dir,
        ctx.progress("track"),
    )  # fmt: skip
    tracks = found.tracks
    summary = dict(
        markers=len(found.names),
        tracked_fraction=round(float((tracks.confidence > 0).mean()), 4),
        warnings=found.problems,
    )
    return TrackOutput(
        tracks.uv, tracks.points, tracks.confidence, tracks.head_pose, found.template,
        found.names, float(ingest.fps), params.backend, params.lift, summary=summary,
    )  # fmt: skip


SPEC = StageSpec.typed(
    "track",
    compute,
    version="3",
    doc="markers (or markerless face mesh) tracked in 2D, lifted to 3D (depth/stereo), smoothed",
    fingerprint=fingerprint,
)
