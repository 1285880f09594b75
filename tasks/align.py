"""Stage ``align``: prepare the high-res scan, align the motion mesh to it, bind, animate.

Outputs the prepared scan (vertices (N,3) m, faces; border slits zipped shut; cut along the
lip seam so the lips can part: ``scan_side`` (N,) says which lip a vertex belongs to and
``scan_parent`` (N,) which uncut vertex it copies), the mouth line (P,3) m, the motion mesh in
the scan frame (T,V,3), the binding of every scan vertex (triangle, barycentric weights,
distance; never across the seam) and the kinematic shape-motion model: scan vertex positions
per frame (T,N,3) float32.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import ConfigDict, Field

from physanim.mesh.params import AlignParams
from physanim.pipeline import StageContext, StageSpec


class AlignStageParams(AlignParams):
    """Alignment settings plus the scan to bind (``face000``: the scan pymeshlab ships)."""

    model_config = ConfigDict(extra="forbid")
    scan: str = Field(
        "face000",
        description="high-res scan (PLY/OBJ/STL, in the marker template's frame) or 'face000'",
    )
    scan_units: str = Field("mm", pattern="^(mm|cm|m)$", description="units of the scan file")


def compute(ctx: StageContext) -> None:
    import numpy as np

    from physanim.face.landmarks import FEATURE_POINTS
    from physanim.face.model import mouth_line_points
    from physanim.mesh.align import align_motion_mesh
    from physanim.mesh.kinematic import animate_bound_points
    from physanim.mesh.remesh import prepare_scan
    from physanim.mesh.scan_io import clean_scan, load_scan
    from physanim.mesh.seam import MouthLine, bind_across_seam, cut_surface

    params: AlignStageParams = ctx.params  # type: ignore[assignment]
    if params.scan == "face000":
        from physanim.capture.actor import build_actor

        actor = build_actor()
        raw_v, raw_f = actor.vertices, actor.faces
    else:
        path = Path(params.scan)
        raw_v, raw_f = clean_scan(*load_scan(path, params.scan_units))  # type: ignore[arg-type]
    scan_v, scan_f = prepare_scan(
        raw_v, raw_f, params.remesh_edge_length_m, params.remesh_iterations,
        params.notch_max_gap_m, params.notch_min_depth_m,
    )  # fmt: skip

    tracked, fitted = ctx.input("track"), ctx.input("fit")
    names = list(tracked.attrs["names"])
    template = tracked["template"][...]
    features = [n for n in FEATURE_POINTS if n in names]
    scan_lms = template[[names.index(n) for n in features]]
    vertex_names = list(fitted.attrs["vertex_names"])
    lm_vertices = np.array([vertex_names.index(n) for n in features])
    triangles = fitted["triangles"][...]
    motion = fitted["motion"][...]

    alignment = align_motion_mesh(
        motion[0], triangles, lm_vertices, scan_v, scan_f, scan_lms,
        features.index("pronasale"), params, ctx.progress("align"),
    )  # fmt: skip
    aligned = alignment.apply(motion)
    # the lip seam: the fitted model's mouth slit, else the line through the mouth corners
    line = mouth_line_points(aligned[0], vertex_names)
    if line is None:
        line = scan_lms[[features.index("ch_R"), features.index("ch_L")]]
    mouth = MouthLine(line, params.lip_band_m)
    cut = cut_surface(scan_v, scan_f, mouth)
    scan_v, scan_f = cut.nodes(scan_v), cut.elements
    binding = bind_across_seam(
        scan_v, cut.side, aligned[0], triangles, mouth, params.binding_candidates
    )
    kinematic = animate_bound_points(scan_v, binding, triangles, aligned)

    ctx.write("scan_vertices", scan_v)
    ctx.write("scan_faces", scan_f)
    ctx.write("scan_side", cut.side)
    ctx.write("scan_parent", cut.parent)
    ctx.write("mouth_line", mouth.points)
    ctx.write("motion", aligned.astype(np.float32))
    ctx.write("triangles", triangles)
    ctx.write("landmark_vertices", lm_vertices)
    ctx.write("landmarks", scan_lms)
    ctx.write_record(binding, prefix="binding")
    ctx.write("kinematic", kinematic.astype(np.float32))
    ctx.out.attrs.update(
        landmark_names=features, fps=float(tracked.attrs["fps"]), lip_band_m=params.lip_band_m
    )
    ctx.summary.update(
        scan_vertices=len(scan_v),
        scan_faces=len(scan_f),
        lip_seam_edges=cut.n_seam_faces,
        median_binding_distance_mm=round(float(np.median(binding.distance)) * 1e3, 3),
    )


SPEC = StageSpec(
    name="align",
    upstream=("track", "fit"),
    params=AlignStageParams,
    version="2",
    compute=compute,
    doc="scan prep + remesh, motion mesh aligned to the scan, binding, kinematic model",
)
