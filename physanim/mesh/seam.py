"""The lip seam: cut a triangle surface or a tet mesh along the lip contact line.

A closed-mouth scan joins the upper and lower lip, so a simulated jaw opening stretches a
sheet across the mouth.  The mouth is modelled by a *mouth line* (the lip contact line, from
the right to the left mouth corner, actor frame: +x the actor's left, +y up) and the seam
surface ``y = h(x)`` through it, swept along the depth axis: between the mouth corners,
elements above it belong to the upper lip and those below to the lower lip.  Cutting
duplicates every node shared by both sides (except at the corners, where the lips join), so
no element bridges the lips and they part when the jaw opens.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from physanim.mesh.binding import Binding, bind_points

#: Node/vertex side labels.
UPPER, NONE, LOWER = 1, 0, -1

#: Vertices of the 4 faces of a tet (the face opposite vertex i).
_TET_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


@dataclass(frozen=True)
class MouthLine:
    """Lip contact polyline ``points`` (P >= 2, 3) m, from the right corner to the left.

    ``band_m``: elements within this vertical distance of the line (and between the corners)
    are assigned to a lip; others are not cut.
    """

    points: NDArray
    band_m: float = 0.015

    def __post_init__(self) -> None:
        p = np.asarray(self.points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
            raise ValueError(f"mouth line needs (P >= 2, 3) points, got shape {p.shape}")
        if np.any(np.diff(p[:, 0]) <= 0):
            raise ValueError(
                "mouth line points must run from the right mouth corner to the left one "
                "with increasing x (actor frame: +x is the actor's left)"
            )

    @property
    def corners(self) -> tuple[float, float]:
        """x (m) of the right and left mouth corners."""
        return float(self.points[0, 0]), float(self.points[-1, 0])

    def element_side(self, nodes: NDArray, elements: NDArray) -> NDArray:
        """UPPER / LOWER / NONE (M,) int8 of the elements (M, k) of ``nodes`` (N, 3) m: their
        centroid's :meth:`side`, but NONE for an element with a node at or past a mouth
        corner, so that a coarse mesh's cut ends inside the corners and never runs on past
        the cut of the finer scan embedded in it (it did by up to a tet's size, and the scan
        triangle between a point of one lip and its uncut neighbour stretched 4.7 times at
        the demo's jaw drop, the tets around it 1.8 at most)."""
        corners = np.asarray(nodes, dtype=np.float64)[np.asarray(elements)]
        x_r, x_l = self.corners
        within = ((corners[..., 0] > x_r) & (corners[..., 0] < x_l)).all(axis=1)
        return np.where(within, self.side(corners.mean(axis=1)), NONE).astype(np.int8)

    def height_at(self, x: NDArray) -> NDArray:
        """Height y (m) of the line at x (m); straight corner-to-corner line beyond the ends."""
        p = np.asarray(self.points, dtype=np.float64)
        slope = (p[-1, 1] - p[0, 1]) / (p[-1, 0] - p[0, 0])
        x = np.asarray(x, dtype=np.float64)
        y = np.interp(x, p[:, 0], p[:, 1])
        y = np.where(x < p[0, 0], p[0, 1] + slope * (x - p[0, 0]), y)
        return np.where(x > p[-1, 0], p[-1, 1] + slope * (x - p[-1, 0]), y)

    def side(self, points: NDArray) -> NDArray:
        """UPPER / LOWER / NONE (N,) int8 of points (N, 3) m: which lip they belong to."""
        p = np.asarray(points, dtype=np.float64)
        x_r, x_l = self.corners
        dy = p[:, 1] - self.height_at(p[:, 0])
        inside = (p[:, 0] > x_r) & (p[:, 0] < x_l) & (np.abs(dy) < self.band_m)
        return np.where(inside, np.where(dy > 0, UPPER, LOWER), NONE).astype(np.int8)


def straight_mouth_line(ch_right: NDArray, ch_left: NDArray, band_m: float = 0.015) -> MouthLine:
    """The mouth line as the straight segment between the mouth corners (3,) m."""
    return MouthLine(np.stack([np.asarray(ch_right), np.asarray(ch_left)]), band_m)


@dataclass(frozen=True)
class Cut:
    """A mesh cut along the seam.

    ``elements``: the elements with cut-side nodes renumbered; ``parent`` (N',): the original
    node of every node (new nodes are appended after the originals); ``side`` (N',) int8:
    UPPER / LOWER for nodes used only by upper / lower-lip elements, else NONE;
    ``n_seam_faces``: element faces (tet faces or triangle edges) the cut opened.
    """

    elements: NDArray
    parent: NDArray
    side: NDArray
    n_seam_faces: int

    def nodes(self, original: NDArray) -> NDArray:
        """Node coordinates (N', ...) of the cut mesh from the originals (N, ...)."""
        return np.asarray(original)[self.parent]

    def face_connected(self) -> tuple[Cut, int]:
        """This cut without the elements outside its largest facet-connected component (their
        unused nodes dropped, the rest renumbered in order), and how many were dropped.

        A tet joined to the rest by an edge or a vertex only (fTetWild leaves a few at thin
        spots; the cut can leave more at the lip corners) turns about that hinge without
        strain: a linear FEM gives it no stiffness there, and it drifted by up to 0.8 m on
        a demo mesh (the flap at the jaw of the FEM tile)."""
        keep = largest_facet_component(self.elements)
        if keep.all():
            return self, 0
        used, elements = np.unique(self.elements[keep], return_inverse=True)
        cut = Cut(elements.reshape(-1, self.elements.shape[1]), self.parent[used],
                  self.side[used], self.n_seam_faces)  # fmt: skip
        return cut, int((~keep).sum())


def largest_facet_component(elements: NDArray) -> NDArray:
    """(M,) bool: the elements (M, 4) tets or (M, 3) triangles of the largest component in
    which neighbours share a facet (a face of a tet, an edge of a triangle)."""
    elements = np.asarray(elements, dtype=np.int64)
    m, k = elements.shape
    facets = _TET_FACES if k == 4 else np.array([[1, 2], [0, 2], [0, 1]])
    keys = np.sort(elements[:, facets].reshape(-1, k - 1), axis=1)
    _, facet = np.unique(keys, axis=0, return_inverse=True)
    facet = facet.ravel()
    incidence = sp.coo_matrix(
        (np.ones(facet.size), (np.repeat(np.arange(m), len(facets)), facet)),
        shape=(m, int(facet.max()) + 1),
    ).tocsr()
    _, label = connected_components(sp.bmat([[None, incidence], [incidence.T, None]]))
    label = label[:m]
    return label == np.bincount(label).argmax()


def _cut(elements: NDArray, element_side: NDArray, facets: NDArray, n_nodes: int) -> Cut:
    """Cut elements (M, k) whose sides (M,) differ across shared facets ((f, k-1) local ids)."""
    elements = np.asarray(elements, dtype=np.int64)
    m, k = elements.shape
    f_nodes = elements[:, facets].reshape(-1, facets.shape[1])  # (M * nf, k-1)
    f_elem = np.repeat(np.arange(m), len(facets))
    _, inv, counts = np.unique(
        np.sort(f_nodes, axis=1), axis=0, return_inverse=True, return_counts=True
    )
    inv = inv.ravel()
    shared = counts[inv] == 2
    order = np.argsort(inv[shared], kind="stable")
    pairs = f_elem[shared][order].reshape(-1, 2)  # the two elements of each interior facet
    pair_nodes = f_nodes[shared][order][::2]  # (P, k-1)
    s = np.asarray(element_side)[pairs]
    seam = s[:, 0] * s[:, 1] == LOWER  # one upper, one lower element
    seam_nodes = np.unique(pair_nodes[seam])
    is_seam_node = np.zeros(n_nodes, dtype=bool)
    is_seam_node[seam_nodes] = True
    # corners (element, node) of seam nodes, linked across every non-seam facet containing it
    corner_e, corner_j = np.nonzero(is_seam_node[elements])
    corner_id = np.full((m, k), -1, dtype=np.int64)
    corner_id[corner_e, corner_j] = np.arange(len(corner_e))
    links_a, links_b = [], []
    keep = ~seam
    for j in range(facets.shape[1]):
        node = pair_nodes[keep, j]
        on = is_seam_node[node]
        e0, e1, n = pairs[keep, 0][on], pairs[keep, 1][on], node[on]
        pos0 = np.argmax(elements[e0] == n[:, None], axis=1)
        pos1 = np.argmax(elements[e1] == n[:, None], axis=1)
        links_a.append(corner_id[e0, pos0])
        links_b.append(corner_id[e1, pos1])
    a, b = np.concatenate(links_a), np.concatenate(links_b)
    n_c = len(corner_e)
    graph = sp.coo_array((np.ones(len(a)), (a, b)), shape=(n_c, n_c))
    _, comp = connected_components(graph, directed=False)
    node_of_corner = elements[corner_e, corner_j]
    # per seam node: its first component keeps the node, every other one gets a new node
    code = node_of_corner * n_c + comp  # (node, component) as one sortable integer
    key, which = np.unique(code, return_inverse=True)
    key_node = key // n_c
    first = np.r_[True, key_node[1:] != key_node[:-1]]
    new_ids = np.where(first, key_node, 0)
    new_ids[~first] = n_nodes + np.arange(int((~first).sum()))
    out = elements.copy()
    out[corner_e, corner_j] = new_ids[which.ravel()]
    parent = np.r_[np.arange(n_nodes), key_node[~first]]
    return Cut(out, parent, node_sides(out, element_side, len(parent)), int(seam.sum()))


def node_sides(elements: NDArray, element_side: NDArray, n_nodes: int) -> NDArray:
    """UPPER / LOWER / NONE (n_nodes,) int8: the lip of the nodes used by the elements (M, k)
    of one lip only (``element_side`` (M,)); NONE for the others (both lips, or neither)."""
    elements, element_side = np.asarray(elements), np.asarray(element_side)
    upper = np.zeros(n_nodes, dtype=bool)
    lower = np.zeros(n_nodes, dtype=bool)
    upper[elements[element_side == UPPER].ravel()] = True
    lower[elements[element_side == LOWER].ravel()] = True
    side = np.zeros(n_nodes, dtype=np.int8)
    side[upper & ~lower] = UPPER
    side[lower & ~upper] = LOWER
    return side


def cut_tets(nodes: NDArray, tets: NDArray, mouth: MouthLine) -> Cut:
    """Cut a tet mesh (nodes (N, 3) m, tets (M, 4)) along the seam surface of ``mouth``."""
    tets = np.asarray(tets, dtype=np.int64)
    return _cut(tets, mouth.element_side(nodes, tets), _TET_FACES, len(nodes))


def cut_surface(vertices: NDArray, faces: NDArray, mouth: MouthLine) -> Cut:
    """Cut a triangle surface (vertices (N, 3) m, faces (F, 3)) along the mouth line."""
    faces = np.asarray(faces, dtype=np.int64)
    centroids = np.asarray(vertices, dtype=np.float64)[faces].mean(axis=1)
    edges = np.array([[1, 2], [0, 2], [0, 1]])
    return _cut(faces, mouth.side(centroids), edges, len(vertices))


def bridging_elements(elements: NDArray, side: NDArray) -> NDArray:
    """Indices of elements (M, k) using both an UPPER and a LOWER node (none after a cut)."""
    s = np.asarray(side)[np.asarray(elements)]
    return np.nonzero((s == UPPER).any(axis=1) & (s == LOWER).any(axis=1))[0]


def bind_across_seam(
    points: NDArray,
    point_side: NDArray,
    vertices: NDArray,
    faces: NDArray,
    mouth: MouthLine,
    candidates: int = 8,
) -> Binding:
    """Closest-point binding of points (N, 3) m to a mesh that never crosses the lip seam.

    A point of the upper lip (``point_side`` UPPER) binds only to triangles not of the lower
    lip, and vice versa (triangle sides from their centroids); other points bind anywhere.
    """
    faces = np.asarray(faces, dtype=np.int64)
    face_side = mouth.side(np.asarray(vertices, dtype=np.float64)[faces].mean(axis=1))
    point_side = np.asarray(point_side)
    parts = []
    for side in (NONE, UPPER, LOWER):
        sel = np.nonzero(point_side == side)[0]
        if len(sel) == 0:
            continue
        allowed = np.nonzero(face_side != -side)[0] if side != NONE else np.arange(len(faces))
        b = bind_points(points[sel], vertices, faces[allowed], candidates=candidates)
        parts.append((sel, allowed[b.triangle], b))
    n = len(point_side)
    out = Binding(
        triangle=np.zeros(n, np.int64),
        weights=np.zeros((n, 3)),
        closest=np.zeros((n, 3)),
        distance=np.zeros(n),
        region=np.zeros(n, np.int8),
    )
    for sel, tri, b in parts:
        out.triangle[sel], out.weights[sel], out.closest[sel] = tri, b.weights, b.closest
        out.distance[sel], out.region[sel] = b.distance, b.region
    return out
