"""Embed points (the high-res scan) in a tet mesh, so they move with its FEM displacement.

Each point takes the barycentric coordinates of the tet that contains it, or of the nearest
tet when it lies just outside (the skin surface of the tets approximates the scan); a point
of the upper lip only uses tets that are not of the lower lip and vice versa, so the lips
part in the embedded surface exactly where the tissue is cut.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from physanim.mesh.kinematic import blend_frames
from physanim.mesh.seam import NONE, MouthLine
from physanim.store.file_cache import FileCache, content_digest


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

    ``point_side`` (N,) and ``tet_side`` (M,): lip sides (``physanim.mesh.seam``); among the
    ``candidates`` tets with the nearest centroids, each point uses the one it is least
    outside of on a compatible side.
    """
    p = np.asarray(points, dtype=np.float64)
    nodes = np.asarray(nodes, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    k = min(candidates, len(tets))
    _, near = cKDTree(nodes[tets].mean(axis=1)).query(p, k=k)
    near = near.reshape(len(p), k)
    corners = nodes[tets[near]]  # (N, k, 4, 3)
    edges = np.swapaxes(corners[:, :, 1:] - corners[:, :, :1], 2, 3)  # (N, k, 3, 3)
    lam = np.linalg.solve(edges, (p[:, None] - corners[:, :, 0])[..., None])[..., 0]
    bary = np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)  # (N, k, 4)
    outside = np.maximum(-bary.min(axis=2), 0.0)
    ps, ts = np.asarray(point_side)[:, None], np.asarray(tet_side)[near]
    wrong = (ps != NONE) & (ts != NONE) & (ps != ts)
    outside[wrong] = np.inf
    best = np.argmin(outside, axis=1)
    rows = np.arange(len(p))
    chosen, weights = near[rows, best], bary[rows, best]
    return sp.csr_array(
        (weights.ravel(), (np.repeat(rows, 4), tets[chosen].ravel())), shape=(len(p), len(nodes))
    )


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
    tet_side = mouth.side(np.asarray(nodes)[tets].mean(axis=1))
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
