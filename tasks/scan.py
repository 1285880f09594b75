"""Stage ``scan``: the high-res scan loaded, cleaned, border slits zipped shut and remeshed.

It reads no other stage, so a run prepares the scan (pymeshlab, about 8 s on the demo) while
it ingests and tracks the capture; ``align`` then binds the prepared scan to the fitted
motion mesh. Before this stage existed, ``align`` (version 3) did both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ConfigDict, Field

from physanim.mesh.params import ScanParams
from physanim.pipeline import DatasetParams, StageContext, StageOutput, StageSpec


class ScanStageParams(ScanParams):
    """The scan to prepare (``face000``: the scan pymeshlab ships) and how."""

    model_config = ConfigDict(extra="forbid")
    scan: str = Field(
        "face000",
        description="high-res scan (PLY/OBJ/STL, in the marker template's frame) or 'face000'",
    )
    scan_units: str = Field("mm", pattern="^(mm|cm|m)$", description="units of the scan file")


@dataclass(frozen=True)
class ScanOutput(StageOutput):
    """The prepared scan: ``vertices`` (N, 3) m, ``faces`` (F, 3), one component with one
    open border (before the lip seam cut, which ``align`` makes)."""

    vertices: np.ndarray
    faces: np.ndarray


def fingerprint(dataset: DatasetParams, params: ScanStageParams) -> Mapping[str, object]:
    """Size and modification time of the scan file (an edited scan re-runs the stage)."""
    from physanim.store import files_fingerprint

    path = Path(params.scan)
    if params.scan == "face000" or not path.is_file():
        return {"scan": params.scan}  # the packaged scan, or a missing file compute reports
    return {"scan": files_fingerprint([path], path.parent)}


def compute(params: ScanStageParams, ctx: StageContext[ScanStageParams]) -> ScanOutput:
    """Load and clean the scan (metres), drop its thin parts, close and fair its slits, remesh
    it isotropically."""
    from physanim.face.scan import load_raw_scan
    from physanim.mesh.remesh import prepare_scan

    report = ctx.progress("scan")
    report(0, 1)
    raw_v, raw_f = load_raw_scan(params.scan, params.scan_units)
    vertices, faces = prepare_scan(
        raw_v, raw_f, params.remesh_edge_length_m, params.remesh_iterations,
        params.notch_max_gap_m, params.notch_min_depth_m, params.min_width_m,
        params.notch_fair_band_m,
    )  # fmt: skip
    report(1, 1)
    summary = dict(raw_vertices=len(raw_v), vertices=len(vertices), faces=len(faces))
    return ScanOutput(vertices, faces, summary=summary)


SPEC = StageSpec.typed(
    "scan",
    compute,
    version="2",
    doc="high-res scan loaded, cleaned, thin parts dropped, border slits zipped shut and "
    "faired, isotropically remeshed",
    fingerprint=fingerprint,
)
