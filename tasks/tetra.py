"""Stage ``tetra``: closed soft-tissue volume behind the skin, fTetWild tets, node labels."""

from __future__ import annotations

from physanim.mesh.params import TetraParams
from physanim.pipeline import StageContext, StageSpec


def compute(ctx: StageContext) -> None:
    """nodes (n,3) m, tets (m,4), skin/bone masks, lip sides, landmark nodes, skin anchors;
    quality report in attrs."""

    from physanim.mesh.seam import MouthLine, cut_tets
    from physanim.mesh.tetra import (
        label_nodes,
        landmark_nodes,
        skin_anchors,
        tetrahedralize_surface,
    )
    from physanim.mesh.tissue import build_tissue_surface

    params: TetraParams = ctx.params  # type: ignore[assignment]
    aligned = ctx.input("align")
    names = list(aligned.attrs["landmark_names"])
    landmarks = aligned["landmarks"][...]
    # the tissue is built from the scan before its lip seam (originals come first), then cut
    parent = aligned["scan_parent"][...]
    n_uncut = int(parent.max()) + 1
    surface = build_tissue_surface(
        aligned["scan_vertices"][:n_uncut],
        parent[aligned["scan_faces"][...]],
        dict(zip(names, landmarks, strict=True)),
        params,
    )
    report = ctx.progress("tetra")
    report(0, 1)
    mesh, quality = tetrahedralize_surface(surface.vertices, surface.faces, params)
    report(1, 1)
    mouth = MouthLine(aligned["mouth_line"][...], float(aligned.attrs["lip_band_m"]))
    cut = cut_tets(mesh.nodes, mesh.tets, mouth)
    nodes = cut.nodes(mesh.nodes)
    labels = label_nodes(mesh, surface, params)
    skin, bone = labels.skin[cut.parent], labels.bone[cut.parent]
    landmark_node, landmark_distance = landmark_nodes(
        nodes, skin, cut.side, landmarks, mouth.side(landmarks)
    )
    ctx.write("nodes", nodes)
    ctx.write("tets", cut.elements)
    ctx.write("skin", skin)
    ctx.write("bone", bone)
    ctx.write("side", cut.side)
    ctx.write("landmark_node", landmark_node)
    ctx.write("landmark_distance", landmark_distance)
    ctx.write("skin_anchor", skin_anchors(nodes, bone, surface))
    ctx.write("thickness", surface.thickness)
    ctx.out.attrs.update(quality=quality.as_dict(), landmark_names=names)
    ctx.summary.update(
        quality.as_dict(), lip_seam_faces=cut.n_seam_faces, seam_nodes=len(nodes) - len(mesh.nodes)
    )


SPEC = StageSpec(
    name="tetra",
    upstream=("align",),
    params=TetraParams,
    version="2",
    compute=compute,
    doc="tissue volume (skin + bone-side offset), fTetWild tets, quality, node labels",
)
