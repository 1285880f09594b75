"""Close narrow notches (slits) that reach into a scan from its outer border.

A range scan loses data in creases it cannot see into: on face000 a slit runs up the chin to
the lower lip and others run up both jowls.  They are part of the outer border, so filling
holes does not close them, and every render shows them as gaps.  A notch is found as two
stretches of the outer border that face each other across a small gap (``max_gap_m``,
measured across the scanner's view axis, +z: the two sides of a crease often lie at
different depths) while lying far apart along the border (more than ``min_depth_m``); it is
closed by zipping its two sides together with a strip of triangles, from the mouth of the
notch to its tip. Where the two sides lay at different depths (on face000 the chin's slit
spans a 7.5 mm step) the zip is a steep wall, drawn in every render as a dark fold:
:func:`fair_zips` then smooths the surface around it into a ramp (the biharmonic fairing of
the vertices near the zip, the rest held).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from physanim.mesh.topology import (
    boundary_edges,
    boundary_vertex_mask,
    directed_edges,
    edge_length_graph,
    uniform_laplacian,
)


def border_loops(faces: NDArray) -> list[NDArray]:
    """Ordered vertex loops (each (L,) int64) of the open border, longest first; each loop
    follows the border half-edges' direction."""
    edges = boundary_edges(faces)
    nxt = dict(zip(edges[:, 0].tolist(), edges[:, 1].tolist(), strict=True))
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(np.asarray(loop, dtype=np.int64))
    return sorted(loops, key=len, reverse=True)


def _notch_mouths(points: NDArray, max_gap_m: float, min_depth_m: float) -> list[tuple[int, int]]:
    """(i, j), i < j, positions in an ordered border loop (L, 3) m where a notch opens: the
    outermost pairs across a gap <= max_gap_m whose arc i..j is longer than min_depth_m and
    is the shorter way round; pairs overlapping a longer one are dropped."""
    seg = np.linalg.norm(np.diff(points, axis=0, append=points[:1]), axis=1)
    s = np.r_[0.0, np.cumsum(seg)[:-1]]
    total = float(seg.sum())
    seen = points[:, :2]  # gaps as the scanner saw them: across the view axis (z)
    pairs = np.array(sorted(cKDTree(seen).query_pairs(max_gap_m)), dtype=np.int64)
    if len(pairs) == 0:
        return []
    arc = s[pairs[:, 1]] - s[pairs[:, 0]]  # i < j: forward arc length
    gap = np.linalg.norm(seen[pairs[:, 0]] - seen[pairs[:, 1]], axis=1)
    deep = (arc > min_depth_m) & (arc < total - min_depth_m) & (arc > 3.0 * gap)
    cand = pairs[deep & (arc <= 0.5 * total)]
    if len(cand) == 0:
        return []
    # keep the outermost: sort by arc length, drop pairs overlapping a kept one
    order = np.argsort(-(s[cand[:, 1]] - s[cand[:, 0]]))
    kept: list[tuple[int, int]] = []
    for i, j in cand[order]:
        if not any(i <= b and a <= j for a, b in kept):
            kept.append((int(i), int(j)))
    return kept


def _zip(
    arc: NDArray, points: NDArray, edges: set[tuple[int, int]]
) -> list[tuple[int, int, int]] | None:
    """Triangles closing the polygon ``arc`` (m+1 vertex ids along the border direction, whose
    positions are ``points`` (m+1, 3)) from the mouth edge arc[0]-arc[m] inwards, each
    oriented against the border half-edge it covers.  Each step adds the shorter of the two
    possible new diagonals unless it is already an edge of the mesh (``edges``: sorted vertex
    pairs), which would make it non-manifold; None when both are."""
    tris = []
    a, b = 0, len(arc) - 1
    while b - a > 1:
        advance_ok = tuple(sorted((arc[a + 1], arc[b]))) not in edges or b - a == 2
        retreat_ok = tuple(sorted((arc[a], arc[b - 1]))) not in edges or b - a == 2
        if not (advance_ok or retreat_ok):
            return None
        shorter = np.linalg.norm(points[a + 1] - points[b]) <= np.linalg.norm(
            points[a] - points[b - 1]
        )
        if advance_ok and (shorter or not retreat_ok):
            tris.append((arc[a + 1], arc[a], arc[b]))
            a += 1
        else:
            tris.append((arc[b], arc[b - 1], arc[a]))
            b -= 1
    return tris


def close_border_notches(
    vertices: NDArray, faces: NDArray, max_gap_m: float, min_depth_m: float
) -> tuple[NDArray, int]:
    """Faces (F', 3) int64 with every notch of the outer border zipped shut, and their count.

    vertices (N, 3) m; faces (F, 3), consistently oriented with one outer border loop.
    """
    faces = np.asarray(faces, dtype=np.int64)
    loops = border_loops(faces)
    if not loops:
        return faces, 0
    loop = loops[0]
    pts = np.asarray(vertices, dtype=np.float64)[loop]
    he = directed_edges(faces)
    edges = set(map(tuple, np.sort(he, axis=1).tolist()))
    new, closed = [], 0
    for i, j in _notch_mouths(pts, max_gap_m, min_depth_m):
        tris = _zip(loop[i : j + 1].tolist(), pts[i : j + 1], edges)
        if tris is not None:
            new += tris
            closed += 1
    if not new:
        return faces, 0
    return np.r_[faces, np.asarray(new, dtype=np.int64)], closed


def fair_zips(vertices: NDArray, faces: NDArray, zipped: NDArray, band_m: float) -> NDArray:
    """Vertices (N, 3) m with the surface around the zip triangles ``faces[zipped]`` faired:
    every vertex within ``band_m`` (m, along the edges) of a zip vertex moves to minimise the
    squared uniform Laplacian (a thin plate over the band: a smooth ramp across a step,
    meeting the held surface around it with a continuous slope), those on the open border in
    depth (z, the scanner's view axis) only, so the outline stays; the others stay exactly. A
    band of 0, or no zip, changes nothing."""
    vertices = np.asarray(vertices, dtype=np.float64)
    seeds = np.unique(np.asarray(faces)[zipped])
    if band_m <= 0 or len(seeds) == 0:
        return vertices
    near = dijkstra(edge_length_graph(vertices, faces), indices=seeds, min_only=True,
                    limit=1.01 * band_m)  # fmt: skip
    band = near < band_m
    lap = uniform_laplacian(faces, len(vertices))
    bilaplacian = sp.csr_array(lap.T @ lap)
    out = vertices.copy()
    inner = band & ~boundary_vertex_mask(faces, len(vertices))
    for axis, free in ((0, inner), (1, inner), (2, band)):
        moved, held = np.nonzero(free)[0], np.nonzero(~free)[0]
        rhs = -(bilaplacian[moved][:, held] @ vertices[held, axis])
        out[moved, axis] = spsolve(sp.csc_array(bilaplacian[moved][:, moved]), rhs)
    return out
