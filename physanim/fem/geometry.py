"""Linear-tetrahedron geometry: shape-function gradients, volumes, inversion checks."""

from __future__ import annotations

import numpy as np


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
    x = nodes[tets]
    edges = x[:, 1:] - x[:, :1]  # (M, 3, 3), rows are edges from node 0
    return np.linalg.det(edges) / 6.0


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


def element_dofs(tets: np.ndarray) -> np.ndarray:
    """Global DOF indices (M, 12) of each tet, 3 DOFs per node interleaved (x, y, z)."""
    return (3 * tets[:, :, None] + np.arange(3)).reshape(len(tets), 12)
