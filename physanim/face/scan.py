"""The high-res scan loaded (the scan stage prepares it) and bound to the fitted motion mesh
(the align stage's computation).

The motion mesh is aligned to the prepared scan by the feature points, the scan cut along the
lip seam (the fitted model's mouth slit, else the line through the mouth corners) so that the
lips can part, every scan vertex bound to the motion mesh (never across the seam) and animated
by it: the kinematic scan.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from numpy.typing import NDArray

from physanim.mesh.binding import Binding
from physanim.mesh.params import AlignParams
from physanim.mesh.seam import MouthLine
from physanim.pipeline import ProgressFn


@dataclass(frozen=True)
class BoundScan:
    """The scan bound to a motion mesh of T frames (N scan vertices, L feature points).

    ``vertices`` (N, 3) m and ``faces`` (F, 3), cut along the lip seam ``mouth``: ``side``
    (N,) the lip of each vertex, ``parent`` (N,) the uncut vertex it copies; ``seam_faces``
    faces along the seam; ``motion`` (T, V, 3) m the motion mesh aligned to the scan;
    ``landmark_names`` (L), ``landmarks`` (L, 3) m on the scan, ``landmark_vertices`` (L,)
    their motion-mesh vertices; ``binding`` of every scan vertex; ``kinematic`` (T, N, 3) m.
    """

    vertices: NDArray
    faces: NDArray
    side: NDArray
    parent: NDArray
    seam_faces: int
    mouth: MouthLine
    motion: NDArray
    landmark_names: list[str]
    landmarks: NDArray
    landmark_vertices: NDArray
    binding: Binding
    kinematic: NDArray


def load_raw_scan(scan: str, units: str) -> tuple[NDArray, NDArray]:
    """Vertices (N, 3) m and faces (F, 3) of ``scan``: a PLY/OBJ/STL file in ``units`` (mm,
    cm, m), cleaned, or ``face000`` (the scan pymeshlab ships, as the demo actor)."""
    if scan == "face000":
        from physanim.capture.actor import build_actor

        actor = build_actor()
        return actor.vertices, actor.faces
    from physanim.mesh.scan_io import clean_scan, load_scan

    return clean_scan(*load_scan(Path(scan), units))


def bind_scan(
    scan_v: NDArray,
    scan_f: NDArray,
    landmark_names: list[str],
    template: NDArray,
    fit_motion: NDArray,
    fit_triangles: NDArray,
    vertex_names: list[str],
    params: AlignParams,
    progress: ProgressFn | None = None,
) -> BoundScan:
    """Align the fitted motion mesh (``fit_motion`` (T, V, 3) m, ``fit_triangles``,
    ``vertex_names``) to the prepared scan ``scan_v`` (N, 3) m, ``scan_f`` (F, 3) by the
    feature points among the tracked ``landmark_names`` (neutral positions ``template`` (K, 3)
    m, on the scan), cut the scan along the lip seam, bind and animate it."""
    from physanim.face.landmarks import FEATURE_POINTS
    from physanim.face.model import mouth_line_points
    from physanim.mesh.align import align_motion_mesh
    from physanim.mesh.kinematic import animate_bound_points
    from physanim.mesh.seam import bind_across_seam, cut_surface
    from physanim.names import name_index

    features = [n for n in FEATURE_POINTS if n in landmark_names]
    scan_lms = template[name_index(landmark_names, features)]
    lm_vertices = name_index(vertex_names, features)
    alignment = align_motion_mesh(
        fit_motion[0], fit_triangles, lm_vertices, scan_v, scan_f, scan_lms,
        int(name_index(features, ["pronasale"])[0]), params, progress,
    )  # fmt: skip
    aligned = alignment.apply(fit_motion)
    line = mouth_line_points(aligned[0], vertex_names)
    if line is None:
        line = scan_lms[name_index(features, ["ch_R", "ch_L"])]
    mouth = MouthLine(line, params.lip_band_m)
    cut = cut_surface(scan_v, scan_f, mouth)
    scan_v, scan_f = cut.nodes(scan_v), cut.elements
    binding = bind_across_seam(
        scan_v, cut.side, aligned[0], fit_triangles, mouth, params.binding_candidates
    )
    kinematic = animate_bound_points(scan_v, binding, fit_triangles, aligned)
    return BoundScan(
        scan_v, scan_f, cut.side, cut.parent, cut.n_seam_faces, mouth, aligned, features,
        scan_lms, lm_vertices, binding, kinematic,
    )  # fmt: skip
