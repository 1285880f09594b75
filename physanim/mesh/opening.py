"""Thin parts of a scan dropped: a morphological opening of the surface from its outer border.

A range scan grazes the sides of a face and keeps slivers there: on face000 a strip of the
jaw's underside, a few millimetres wide, hangs off the actor's left jowl by a thinner bridge,
and the cheek border is serrated. No camera in front of the face sees such a strip, so
tracking cannot follow it, and zipping the border notch beside it fans folded triangles
across to it; in every render it stood out as a flap. Opening the surface removes every part
narrower than a width while leaving the wider surface exactly as it was:

1. erode: keep the faces whose vertices all lie at least ``width / 2`` from the outer border
   (geodesic distance along the edges, Dijkstra from every border vertex);
2. keep the largest (by area) connected part of what is left: a part joined to the face only
   through a neck narrower than the width is cut off here;
3. dilate: bring back every face whose vertices all lie within ``width / 2`` of that part.

Only the outer border erodes: an inner hole (the scanner's lost mouth) is closed later and
must not eat the lips around it. Written here because pymeshlab's selection dilate/erode work
in rings of faces, not in metres, and neither it nor Open3D has a geodesic opening.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra

from physanim.mesh.notches import border_loops
from physanim.mesh.scan_io import largest_component
from physanim.mesh.topology import edge_length_graph, triangle_areas


def drop_thin_parts(vertices: NDArray, faces: NDArray, min_width_m: float) -> NDArray:
    """Faces (F', 3) int64 of ``faces`` (F, 3) without the parts narrower than ``min_width_m``
    (m) along the outer border, nor those joined to the face through a narrower neck;
    ``vertices`` (N, 3) m are not changed (drop the unreferenced ones after). A width of 0,
    or a mesh without a border, keeps every face."""
    faces = np.asarray(faces, dtype=np.int64)
    loops = border_loops(faces)
    if min_width_m <= 0 or not loops:
        return faces
    vertices = np.asarray(vertices, dtype=np.float64)
    radius = 0.5 * min_width_m
    graph = edge_length_graph(vertices, faces)
    from_border = dijkstra(graph, indices=loops[0], min_only=True, limit=2.0 * radius)
    core = faces[(from_border[faces] >= radius).all(axis=1)]
    if len(core) == 0:
        raise ValueError(
            f"scan.min_width_m {min_width_m}: no part of the scan is that wide (its units? a "
            "face is about 0.15 m across)"
        )
    kept = np.unique(largest_component(core, len(vertices), triangle_areas(vertices, core)))
    from_core = dijkstra(graph, indices=kept, min_only=True, limit=1.5 * radius)
    return faces[(from_core[faces] <= radius * (1.0 + 1e-9)).all(axis=1)]
