"""Linear-tetrahedron geometry: shape-function gradients, volumes, inversion checks."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

import physanim.fem.numba_threads  # noqa: F401  (threading layer, before the parallel kernel)


def validate_mesh(nodes: np.ndarray, tets: np.ndarray) -> None:
    """Check shapes, dtypes and index range of a tet mesh; raise ValueError naming the array."""
    if nodes.ndim != 2 or nodes.shape[1] != 3:
        raise ValueError(f"nodes must have shape (N, 3) in metres, got {nodes.shape}")
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise ValueError(f"tets must have shape (M, 4) of node indices, got {tets.shape}")
    if not np.issubdtype(tets.dtype, np.integer):
        raise ValueError(f"tets must be an integer array, got dtype {tets.dtype}")
    if tets.size and (tets.min() < 0 or tets.max() >= len(nodes)):
        raise ValueError(
            f"tets index nodes outside [0, {len(nodes)}): min {tets.min()}, max {tets.max()}"
        )
    if not np.isfinite(nodes).all():
        raise ValueError("nodes contain NaN or Inf coordinates")


def signed_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed tet volumes (M,) in m^3; positive for positively oriented tets."""
    out = np.empty(len(tets))
    _signed_volumes(np.ascontiguousarray(nodes, dtype=np.float64), np.ascontiguousarray(tets), out)
    return out


# compiled: it runs once per output frame, where the numpy version (gather nodes[tets], then
# np.linalg.det, an LU per tet) took ~5 ms on the demo mesh
@njit(cache=True, parallel=True)
def _signed_volumes(nodes, tets, out):
    for e in prange(tets.shape[0]):
        i, j, k, m = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
        x, y, z = nodes[i, 0], nodes[i, 1], nodes[i, 2]
        a0, a1, a2 = nodes[j, 0] - x, nodes[j, 1] - y, nodes[j, 2] - z
        b0, b1, b2 = nodes[k, 0] - x, nodes[k, 1] - y, nodes[k, 2] - z
        c0, c1, c2 = nodes[m, 0] - x, nodes[m, 1] - y, nodes[m, 2] - z
        det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
        out[e] = det / 6.0


def shape_gradients(nodes: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the 4 linear shape functions and tet volumes.

    Returns ``grads`` (M, 4, 3) in 1/m (``grads[e, a]`` = grad N_a on tet e) and
    ``volumes`` (M,) in m^3. Raises ValueError if any tet is inverted or degenerate.
    """
    validate_mesh(nodes, tets)
    x = nodes[tets]
    jac = np.swapaxes(x[:, 1:] - x[:, :1], 1, 2)  # (M, 3, 3), columns are edges
    vol = np.linalg.det(jac) / 6.0
    scale = np.abs(x - x.mean(axis=1, keepdims=True)).max(axis=(1, 2)) ** 3
    bad = np.flatnonzero(vol <= 1e-12 * np.maximum(scale, np.finfo(float).tiny))
    if bad.size:
        raise ValueError(
            f"tets: {bad.size} tets are inverted or degenerate at rest (first: tet {bad[0]}, "
            f"volume {vol[bad[0]]:.3e} m^3); reorder their nodes to positive orientation"
        )
    inv = np.linalg.inv(jac)  # rows of inv are grad of barycentric coords 1..3
    grads = np.empty((len(tets), 4, 3))
    grads[:, 1:] = inv
    grads[:, 0] = -inv.sum(axis=1)
    return grads, vol


def node_dofs(nodes: np.ndarray) -> np.ndarray:
    """Global DOF indices of node ids (..., k) -> (..., 3k), 3 DOFs per node interleaved
    (x, y, z): (n,) ids give (3n,) DOFs."""
    nodes = np.asarray(nodes)
    return (3 * nodes[..., None] + np.arange(3)).reshape(*nodes.shape[:-1], -1)


def element_dofs(tets: np.ndarray) -> np.ndarray:
    """Global DOF indices (M, 12) of each tet, 3 DOFs per node interleaved (x, y, z)."""
    return node_dofs(tets)
