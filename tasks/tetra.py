"""Stage ``tetra``: closed soft-tissue volume behind the skin, fTetWild tets, node labels.

Version history: CHANGELOG.md.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from physanim.mesh.params import TetraParams
from physanim.pipeline import DatasetParams, StageContext, StageOutput, StageSpec
from tasks.align import AlignOutput


@dataclass(frozen=True)
class TetraOutput(StageOutput):
    """The tissue volume: ``nodes`` (n, 3) m, ``tets`` (m, 4), cut along the lip seam;
    ``skin`` / ``bone`` (n,) bool masks; ``side`` (n,) lip side; ``landmark_node`` (L,) the
    skin node of each of align's landmarks, ``landmark_distance`` (L,) m from it;
    ``skin_anchor`` (n,) the bone node behind each skin node; ``thickness`` (N_scan,) m of
    the tissue behind each scan vertex; ``quality`` the mesh quality report."""

    nodes: np.ndarray
    tets: np.ndarray
    skin: np.ndarray
    bone: np.ndarray
    side: np.ndarray
    landmark_node: np.ndarray
    landmark_distance: np.ndarray
    skin_anchor: np.ndarray
    thickness: np.ndarray
    quality: dict[str, Any]


def compute(params: TetraParams, align: AlignOutput, ctx: StageContext[TetraParams]) -> TetraOutput:
    """nodes (n,3) m, tets (m,4), skin/bone masks, lip sides, landmark nodes, skin anchors;
    quality report in attrs."""
    from physanim.mesh.seam import cut_tets
    from physanim.mesh.sizing import region_quality, regional_sizing
    from physanim.mesh.tetra import (
        label_nodes,
        landmark_nodes,
        load_tet_mesh,
        skin_anchors,
        tetrahedralize_surface,
    )
    from physanim.mesh.tissue import build_tissue_surface

    # the tissue is built from the scan before its lip seam (originals come first), then cut
    n_uncut = int(align.scan_parent.max()) + 1
    surface = build_tissue_surface(
        align.scan_vertices[:n_uncut],
        align.scan_parent[align.scan_faces],
        align.landmark_positions(),
        params,
    )
    report = ctx.progress("tetra")
    report(0, 1)
    feature_points = align.landmark_positions()
    if params.mesh_file:
        mesh, quality = load_tet_mesh(params.mesh_file, surface.vertices, surface.faces, params)
    else:
        graded = None
        if params.refine.enabled:
            skin = surface.vertices[: surface.n_skin]
            graded = regional_sizing(skin, feature_points, params)
        mesh, quality = tetrahedralize_surface(surface.vertices, surface.faces, params, graded)
    report(1, 1)
    regions = region_quality(mesh.nodes, mesh.tets, feature_points, params.refine)
    mouth = align.mouth()
    cut, hinged = cut_tets(mesh.nodes, mesh.tets, mouth).face_connected()
    nodes = cut.nodes(mesh.nodes)
    labels = label_nodes(mesh, surface, params)
    skin, bone = labels.skin[cut.parent], labels.bone[cut.parent]
    landmark_node, landmark_distance = landmark_nodes(
        nodes, skin, cut.side, align.landmarks, mouth.side(align.landmarks)
    )
    summary = dict(
        quality.as_dict(), regions=regions, lip_seam_faces=cut.n_seam_faces,
        seam_nodes=len(nodes) - len(np.unique(cut.parent)), hinged_tets_dropped=hinged,
    )  # fmt: skip
    return TetraOutput(
        nodes, cut.elements, skin, bone, cut.side, landmark_node, landmark_distance,
        skin_anchors(nodes, bone, surface), surface.thickness,
        dict(quality.as_dict(), regions=regions), summary=summary,
    )  # fmt: skip


def fingerprint(dataset: DatasetParams, params: TetraParams) -> Mapping[str, Any]:
    """The content of ``tetra.mesh_file`` when one is given (an edited mesh re-runs tetra)."""
    if not params.mesh_file:
        return {}
    path = Path(params.mesh_file)
    return {"mesh_file": hashlib.sha256(path.read_bytes()).hexdigest() if path.exists() else None}


SPEC = StageSpec.typed(
    "tetra",
    compute,
    version="6",
    doc="tissue volume (skin + bone-side offset), fTetWild tets (optionally finer in named "
    "regions, coarser deep), quality per region, node labels",
    fingerprint=fingerprint,
    varies=True,  # fTetWild's mesh differs from run to run, even on one thread
)
