"""Embed points (the high-res scan) in a tet mesh, so they move with its FEM displacement.

Each point inside the tets takes the barycentric coordinates of the tet that contains it; a
point outside (the skin surface of the tets approximates the scan: 38 % of the demo scan's
vertices lie outside, 0.16 mm median, up to 2 mm) moves with its closest point on the tet
mesh's boundary. Not with the nearest tet's linear field extrapolated: two neighbouring scan
vertices outside two different tets then follow two different extrapolations, and where the
tissue strains (the jowl and chin at the jaw drop) the triangle between them turned over (4 on
the demo; 0 on the boundary, whose interpolation is continuous). A point of the upper lip only
uses tets (and boundary faces) that are not of the lower lip and vice versa, so the lips part
in the embedded surface exactly where the tissue is cut.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from physanim.mesh.kinematic import blend_frames
from physanim.mesh.seam import NONE, MouthLine, node_sides
from physanim.store.file_cache import FileCache, content_digest

#: A point at most this far outside a tet in barycentric terms (-min weight) is inside it.
OUTSIDE_TOLERANCE = 1e-9


def embedding_matrix(
    points: NDArray,
    point_side: NDArray,
    nodes: NDArray,
    tets: NDArray,
    tet_side: NDArray,
    candidates: int = 24,
) -> sp.csr_array:
    """(N, n) sparse W: W @ u gives the displacements of points (N, 3) m from the node
    displacements u (n, ...) of a tet mesh (nodes (n, 3) m, tets (M, 4)).

    ``point_side`` (N,) and ``tet_side`` (M,): lip sides (``physanim.mesh.seam``). A tet (or
    boundary face) is compatible with a point of one lip when it is not of the other lip and
    has no node of the other lip only: at the end of the cut a tet of neither lip holds nodes
    of one, and a lower-lip scan vertex that followed an upper-lip node there dropped half as
    far as its neighbours at the jaw drop (its triangle stretched 3.4 times). A point
    inside a compatible tet takes its barycentric coordinates (searched among the
    ``candidates`` tets with the nearest centroids, then, for a point in none of them, among
    every tet whose centroid is close enough to contain it); a point in none moves with its
    closest point on the boundary (:func:`on_boundary`).
    """
    p = np.asarray(points, dtype=np.float64)
    nodes = np.asarray(nodes, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    point_side, tet_side = np.asarray(point_side), np.asarray(tet_side)
    centroids = nodes[tets].mean(axis=1)
    tree = cKDTree(centroids)
    k = min(candidates, len(tets))
    near = tree.query(p, k=k)[1].reshape(len(p), k)
    rows = np.repeat(np.arange(len(p)), k)
    node_side = node_sides(tets, tet_side, len(nodes))
    chosen, weights = _containing(
        p, point_side, tets, node_side, tet_side, rows, near.ravel(), nodes
    )
    missed = np.flatnonzero(chosen < 0)
    if len(missed):
        # a tet contains a point only within its largest centroid-to-corner distance
        reach = float(np.linalg.norm(nodes[tets] - centroids[:, None], axis=2).max())
        found = tree.query_ball_point(p[missed], reach)
        rows = np.repeat(missed, [len(f) for f in found])
        tried = np.fromiter((t for f in found for t in f), np.int64, len(rows))
        again = _containing(p, point_side, tets, node_side, tet_side, rows, tried, nodes)
        chosen[missed], weights[missed] = again[0][missed], again[1][missed]
    inside = np.flatnonzero(chosen >= 0)
    within = sp.csr_array(
        (weights[inside].ravel(), (np.repeat(inside, 4), tets[chosen[inside]].ravel())),
        shape=(len(p), len(nodes)),
    )
    return within + on_boundary(p, point_side, nodes, tets, tet_side, chosen < 0, node_side)


def compatible(point_side: NDArray, element_side: NDArray, corner_sides: NDArray) -> NDArray:
    """(P,) bool: may a point of lip ``point_side`` (P,) follow an element of lip
    ``element_side`` (P,) whose nodes are of lips ``corner_sides`` (P, k)? Yes for a point of
    neither lip; else when the element is not of the other lip and has no node of it."""
    other = -np.asarray(point_side)
    return (other == NONE) | (
        (element_side != other) & ~(corner_sides == other[:, None]).any(axis=1)
    )


def _containing(
    points: NDArray,
    point_side: NDArray,
    tets: NDArray,
    node_side: NDArray,
    tet_side: NDArray,
    rows: NDArray,
    tried: NDArray,
    nodes: NDArray,
) -> tuple[NDArray, NDArray]:
    """Of the pairs (point ``rows`` (P,), tet ``tried`` (P,)): per point (N,) the
    :func:`compatible` tet that contains it (-1: none of its pairs) and its barycentric
    coordinates (N, 4) there (0 where none)."""
    corners = nodes[tets[tried]]  # (P, 4, 3)
    edges = np.swapaxes(corners[:, 1:] - corners[:, :1], 1, 2)  # (P, 3, 3)
    lam = np.linalg.solve(edges, (points[rows] - corners[:, 0])[..., None])[..., 0]
    bary = np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)  # (P, 4)
    fits = (bary.min(axis=1) >= -OUTSIDE_TOLERANCE) & compatible(
        point_side[rows], tet_side[tried], node_side[tets[tried]]
    )
    chosen = np.full(len(points), -1)
    weights = np.zeros((len(points), 4))
    chosen[rows[fits]], weights[rows[fits]] = tried[fits], bary[fits]  # any containing tet
    return chosen, weights


def on_boundary(
    points: NDArray,
    point_side: NDArray,
    nodes: NDArray,
    tets: NDArray,
    tet_side: NDArray,
    which: NDArray,
    node_side: NDArray,
) -> sp.csr_array:
    """(N, n) sparse W whose rows ``which`` (N,) bool interpolate the node values at each
    point's closest point on the boundary of the tets (among the :func:`compatible` faces:
    their tet's lip ``tet_side`` (M,), their nodes' ``node_side`` (n,)); the other rows are
    empty."""
    from physanim.mesh.binding import bind_points_bvh
    from physanim.mesh.kinematic import blend_matrix
    from physanim.mesh.tetra import boundary_faces_and_tets

    faces, owner = boundary_faces_and_tets(tets)
    face_side = tet_side[owner]
    out = sp.csr_array((len(points), len(nodes)))
    for side in np.unique(point_side[which]):
        rows = np.flatnonzero(which & (point_side == side))
        usable = compatible(np.full(len(faces), side), face_side, node_side[faces])
        bound = blend_matrix(bind_points_bvh(points[rows], nodes, faces[usable]), faces[usable],
                             len(nodes)).tocoo()  # fmt: skip
        out = out + sp.csr_array(
            (bound.data, (rows[bound.row], bound.col)), shape=(len(points), len(nodes))
        )
    return out


def embedded_displacements(
    points: NDArray,
    point_side: NDArray,
    nodes: NDArray,
    tets: NDArray,
    mouth: MouthLine,
    displacements: NDArray,
    cache: FileCache | None = None,
) -> NDArray:
    """Displacements (T, N, 3) m of ``points`` (N, 3) m (lip sides ``point_side`` (N,))
    embedded in a tet mesh (``nodes`` (n, 3) m, ``tets`` (M, 4)) cut along the lip seam
    ``mouth``, from the node displacements (T, n, 3) m. ``cache``: keeps the embedding by the
    content of its inputs (a material edit does not change it)."""
    tet_side = mouth.element_side(nodes, tets)
    args = (points, point_side, nodes, tets, tet_side)
    if cache is None:
        return blend_frames(embedding_matrix(*args), displacements)
    digest = content_digest(Path(__file__).read_bytes(), *map(np.asarray, args))
    found = cache.fetch(digest, ".npz")
    if found is not None:
        w = sp.csr_array(sp.load_npz(found))
    else:
        w = embedding_matrix(*args)
        cache.put(digest, ".npz", lambda path: sp.save_npz(path, sp.csr_matrix(w)))
    return blend_frames(w, displacements)
