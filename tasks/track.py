"""Stage ``track``: painted markers tracked in the colour frames and lifted to 3D with depth."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping

from pydantic import BaseModel, ConfigDict, Field

from physanim.pipeline import DatasetParams, StageContext, StageSpec
from physanim.tracking.params import TrackParams


class TrackStageParams(TrackParams):
    """Tracking settings plus the marker template (path relative to the dataset directory)."""

    model_config = ConfigDict(extra="forbid")
    template: str = Field(
        "ground_truth.zarr", description="marker template: JSON or Zarr, relative to the dataset"
    )


def fingerprint(dataset: DatasetParams, params: BaseModel) -> Mapping[str, str]:
    """Content hash of the marker template (names and neutral positions)."""
    from physanim.tracking.template import load_marker_template

    path = dataset.path / params.template  # type: ignore[attr-defined]
    if not path.exists():
        return {"template": "missing"}
    names, pos = load_marker_template(path)
    digest = hashlib.sha256(("|".join(names)).encode() + pos.tobytes()).hexdigest()
    return {"template": digest}


def compute(ctx: StageContext) -> None:
    """uv (T,K,2) px, points (T,K,3) m camera frame, confidence (T,K), head_pose (T,4,4)."""
    from physanim.tracking.template import load_marker_template
    from physanim.tracking.track import track_markers_rgbd

    params: TrackStageParams = ctx.params  # type: ignore[assignment]
    names, template = load_marker_template(ctx.dataset_dir / params.template)
    cap = ctx.input("ingest")
    tracks = track_markers_rgbd(
        cap["color"][...],
        cap["depth"][...],
        cap["K"][...],
        template,
        float(cap.attrs["fps"]),
        TrackParams.model_validate(params.model_dump(exclude={"template"})),
        ctx.progress("track"),
    )
    ctx.write_record(tracks)
    ctx.write("template", template)
    ctx.out.attrs["names"] = names
    seen = tracks.confidence > 0
    ctx.summary.update(markers=len(names), tracked_fraction=round(float(seen.mean()), 4))


SPEC = StageSpec(
    name="track",
    upstream=("ingest",),
    params=TrackStageParams,
    version="1",
    compute=compute,
    doc="marker detection, labelling, LK tracking, depth lifting, smoothing",
    fingerprint=fingerprint,
)
