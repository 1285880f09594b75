"""Combinatorial helpers for triangle meshes: edges, borders, watertightness, Laplacian."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit


def directed_edges(faces: np.ndarray) -> np.ndarray:
    """(3F, 2) directed half-edges (a->b, b->c, c->a) of (F, 3) triangles."""
    faces = np.asarray(faces, dtype=np.int64)
    return np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)


def boundary_edges(faces: np.ndarray) -> np.ndarray:
    """(B, 2) directed half-edges used by exactly one triangle (the open border), as oriented
    in their triangle."""
    he = directed_edges(faces)
    key = np.sort(he, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return he[counts[inverse.ravel()] == 1]


def boundary_vertex_mask(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(V,) bool: vertices on an open border of the triangle mesh."""
    mask = np.zeros(n_vertices, dtype=bool)
    mask[boundary_edges(faces).ravel()] = True
    return mask


def watertight_problems(faces: np.ndarray) -> list[str]:
    """Reasons why (F, 3) triangles are not a closed, consistently oriented 2-manifold; [] if
    they are: every undirected edge in exactly two triangles, traversed once each way."""
    he = directed_edges(faces)
    problems = []
    key = np.sort(he, axis=1)
    _, counts = np.unique(key, axis=0, return_counts=True)
    if np.any(counts == 1):
        problems.append(f"{int(np.sum(counts == 1))} open (border) edges")
    if np.any(counts > 2):
        problems.append(f"{int(np.sum(counts > 2))} non-manifold edges (in 3+ triangles)")
    _, dcounts = np.unique(he, axis=0, return_counts=True)
    if np.any(dcounts > 1):
        problems.append(f"{int(np.sum(dcounts > 1))} inconsistently oriented edges")
    return problems


def uniform_laplacian(faces: np.ndarray, n_vertices: int) -> sp.csr_array:
    """Graph Laplacian L = D - A of a triangle mesh, (V, V) sparse (row sums zero)."""
    he = directed_edges(faces)
    i = np.r_[he[:, 0], he[:, 1]]
    j = np.r_[he[:, 1], he[:, 0]]
    adj = sp.csr_array((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices))
    adj.data[:] = 1.0  # duplicate entries were summed: reset to a 0/1 adjacency
    deg = np.asarray(adj.sum(axis=1)).ravel()
    return (sp.diags_array(deg) - adj).tocsr()


def edge_length_graph(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_array:
    """Symmetric (V, V) sparse graph of the mesh edges weighted by their length, m (for
    geodesic distances along the edges, ``scipy.sparse.csgraph.dijkstra``)."""
    e = np.unique(np.sort(directed_edges(faces), axis=1), axis=0)
    w = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    rows, cols = np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]]
    return sp.coo_array((np.r_[w, w], (rows, cols)), shape=(len(vertices),) * 2).tocsr()


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals of a triangle mesh (zero for isolated vertices)."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    n = np.zeros_like(v)
    accumulate_face_normals(v, f, n)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(norm > 0.0, norm, 1.0)


# compiled: the renders take every frame's normals, and the numpy form (cross products, then a
# bincount per axis) took 17 ms for the 166k triangles of face000 against 1 ms here
@njit(cache=True, nogil=True)
def accumulate_face_normals(v: np.ndarray, f: np.ndarray, n: np.ndarray) -> None:
    """Add each triangle's (2 x area x unit normal) of vertices ``v`` (V, 3), faces ``f``
    (F, 3) to its three vertices' rows of ``n`` (V, 3), in their precision (compiled: callable
    from other compiled kernels)."""
    for t in range(f.shape[0]):
        a, b, c = f[t, 0], f[t, 1], f[t, 2]
        ux, uy, uz = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        wx, wy, wz = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
        cx, cy, cz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
        for i in (a, b, c):
            n[i, 0] += cx
            n[i, 1] += cy
            n[i, 2] += cz


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) triangle areas in the square of the vertex unit."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


def vertex_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V,) area attributed to each vertex: a third of every incident triangle's area."""
    f = np.asarray(faces, dtype=np.int64)
    third = np.repeat(triangle_areas(vertices, f) / 3.0, 3)
    return np.bincount(f.ravel(), third, minlength=len(vertices))
