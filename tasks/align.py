"""Stage ``align``: align the motion mesh to the prepared scan (stage ``scan``), bind, animate.

Outputs the scan cut along the lip seam (so the lips can part), the mouth line, the motion
mesh in the scan frame, the binding of every scan vertex (never across the seam) and the
kinematic shape-motion model (:class:`AlignOutput`). Version history: CHANGELOG.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from physanim.mesh.binding import Binding
from physanim.mesh.params import AlignParams
from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.fit import FitOutput
from tasks.scan import ScanOutput
from tasks.track import TrackOutput

if TYPE_CHECKING:
    from physanim.mesh.seam import MouthLine


@dataclass(frozen=True)
class AlignOutput(StageOutput):
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


def compute(
    params: AlignParams,
    track: TrackOutput,
    fit: FitOutput,
    scan: ScanOutput,
    ctx: StageContext[AlignParams],
) -> AlignOutput:
    """Alignment of the motion mesh to the prepared scan, lip seam, binding, kinematic scan."""
    from physanim.face.scan import bind_scan

    bound = bind_scan(
        scan.vertices, scan.faces, track.landmark_names, track.template, fit.motion,
        fit.triangles, fit.vertex_names, params, ctx.progress("align"),
    )  # fmt: skip
    summary = dict(
        scan_vertices=len(bound.vertices),
        scan_faces=len(bound.faces),
        lip_seam_edges=bound.seam_faces,
        median_binding_distance_mm=round(float(np.median(bound.binding.distance)) * 1e3, 3),
    )
    return AlignOutput(
        bound.vertices, bound.faces, bound.side, bound.parent, bound.mouth.points,
        bound.motion.astype(np.float32), fit.triangles, bound.landmark_vertices,
        bound.landmarks, bound.binding, bound.kinematic.astype(np.float32),
        bound.landmark_names, params.lip_band_m, summary=summary,
    )  # fmt: skip


SPEC = StageSpec.typed(
    "align",
    compute,
    version="4",
    doc="motion mesh aligned to the prepared scan, lip seam cut, binding, kinematic model",
)
