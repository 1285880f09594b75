"""Stage ``tetra``: closed soft-tissue volume behind the skin, fTetWild tets, node labels."""

from __future__ import annotations

from physanim.mesh.params import TetraParams
from physanim.pipeline import StageContext, StageSpec


def compute(ctx: StageContext) -> None:
    """nodes (n,3) m, tets (m,4), skin/bone masks, landmark nodes; quality report in attrs."""
    from physanim.mesh.tetra import label_nodes, tetrahedralize_surface
    from physanim.mesh.tissue import build_tissue_surface

    params: TetraParams = ctx.params  # type: ignore[assignment]
    aligned = ctx.input("align")
    names = list(aligned.attrs["landmark_names"])
    landmarks = aligned["landmarks"][...]
    surface = build_tissue_surface(
        aligned["scan_vertices"][...],
        aligned["scan_faces"][...],
        dict(zip(names, landmarks, strict=True)),
        params,
    )
    report = ctx.progress("tetra")
    report(0, 1)
    mesh, quality = tetrahedralize_surface(surface.vertices, surface.faces, params)
    report(1, 1)
    labels = label_nodes(mesh, surface, landmarks, params)
    ctx.write("nodes", mesh.nodes)
    ctx.write("tets", mesh.tets)
    ctx.write_record(labels)
    ctx.write("thickness", surface.thickness)
    ctx.out.attrs.update(quality=quality.as_dict(), landmark_names=names)
    ctx.summary.update(quality.as_dict())


SPEC = StageSpec(
    name="tetra",
    upstream=("align",),
    params=TetraParams,
    version="1",
    compute=compute,
    doc="tissue volume (skin + bone-side offset), fTetWild tets, quality, node labels",
)
