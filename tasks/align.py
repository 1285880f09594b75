"""Stage ``align``: prepare the high-res scan, align the motion mesh to it, bind, animate.

Outputs the prepared scan (border slits zipped shut, cut along the lip seam so the lips can
part), the mouth line, the motion mesh in the scan frame, the binding of every scan vertex
(never across the seam) and the kinematic shape-motion model (:class:`AlignOutput`).

Version 3: ``fps`` is no longer copied into this output (read it from ``track``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from pydantic import ConfigDict, Field

from physanim.mesh.binding import Binding
from physanim.mesh.params import AlignParams
from physanim.pipeline import DatasetParams, StageContext, StageSpec
from tasks.fit import FitOutput
from tasks.track import TrackOutput

if TYPE_CHECKING:
    from physanim.mesh.seam import MouthLine


class AlignStageParams(AlignParams):
    """Alignment settings plus the scan to bind (``face000``: the scan pymeshlab ships)."""

    model_config = ConfigDict(extra="forbid")
    scan: str = Field(
        "face000",
        description="high-res scan (PLY/OBJ/STL, in the marker template's frame) or 'face000'",
    )
    scan_units: str = Field("mm", pattern="^(mm|cm|m)$", description="units of the scan file")


@dataclass(frozen=True)
class AlignOutput:
    """The scan, bound to the motion mesh and animated by it (T frames, N scan vertices).

    ``scan_vertices`` (N, 3) m, ``scan_faces`` (F, 3), cut along the lip seam: ``scan_side``
    (N,) which lip a vertex belongs to, ``scan_parent`` (N,) which uncut vertex it copies
    (the uncut vertices come first); ``mouth_line`` (P, 3) m and ``lip_band_m`` m, the lip
    seam; ``motion`` (T, V, 3) float32 m, the motion mesh in the scan frame, ``triangles``
    (F_m, 3); ``landmarks`` (L, 3) m the feature points on the scan, ``landmark_names`` (L),
    ``landmark_vertices`` (L,) their motion-mesh vertices; ``binding`` of every scan vertex;
    ``kinematic`` (T, N, 3) float32 m, the kinematic scan (read lazily: a Zarr array).
    """

    scan_vertices: np.ndarray
    scan_faces: np.ndarray
    scan_side: np.ndarray
    scan_parent: np.ndarray
    mouth_line: np.ndarray
    motion: np.ndarray
    triangles: np.ndarray
    landmark_vertices: np.ndarray
    landmarks: np.ndarray
    binding: Binding
    kinematic: np.ndarray = field(metadata={"lazy": True})
    landmark_names: list[str] = field(default_factory=list)
    lip_band_m: float = 0.0

    def mouth(self) -> MouthLine:
        """The lip seam as a :class:`~physanim.mesh.seam.MouthLine`."""
        from physanim.mesh.seam import MouthLine

        return MouthLine(self.mouth_line, float(self.lip_band_m))

    def landmark_positions(self) -> dict[str, np.ndarray]:
        """Feature point name -> (3,) m position on the scan."""
        return dict(zip(self.landmark_names, self.landmarks, strict=True))


def fingerprint(dataset: DatasetParams, params: AlignStageParams) -> Mapping[str, object]:
    """Size and modification time of the scan file (an edited scan re-runs align)."""
    from physanim.store import files_fingerprint

    path = Path(params.scan)
    if params.scan == "face000" or not path.is_file():
        return {"scan": params.scan}  # the packaged scan, or a missing file align reports
    return {"scan": files_fingerprint([path], path.parent)}


def compute(
    params: AlignStageParams,
    track: TrackOutput,
    fit: FitOutput,
    ctx: StageContext[AlignStageParams],
) -> AlignOutput:
    """Scan prep, alignment of the motion mesh to the scan, lip seam, binding, kinematic scan."""
    from physanim.face.scan import bind_scan, load_raw_scan

    raw_v, raw_f = load_raw_scan(params.scan, params.scan_units)
    scan = bind_scan(
        raw_v, raw_f, track.landmark_names, track.template, fit.motion, fit.triangles,
        fit.vertex_names, params, ctx.progress("align"),
    )  # fmt: skip
    ctx.summary.update(
        scan_vertices=len(scan.vertices),
        scan_faces=len(scan.faces),
        lip_seam_edges=scan.seam_faces,
        median_binding_distance_mm=round(float(np.median(scan.binding.distance)) * 1e3, 3),
    )
    return AlignOutput(
        scan.vertices, scan.faces, scan.side, scan.parent, scan.mouth.points,
        scan.motion.astype(np.float32), fit.triangles, scan.landmark_vertices, scan.landmarks,
        scan.binding, scan.kinematic.astype(np.float32), scan.landmark_names, params.lip_band_m,
    )  # fmt: skip


SPEC = StageSpec.typed(
    "align",
    compute,
    version="3",
    doc="scan prep + remesh, motion mesh aligned to the scan, binding, kinematic model",
    fingerprint=fingerprint,
)
