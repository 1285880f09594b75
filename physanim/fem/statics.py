"""Linear static solve with prescribed DOFs partitioned out, and support reactions."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from physanim.fem.linsolve import factorize


def free_dofs(n_dofs: int, prescribed: np.ndarray) -> np.ndarray:
    """Indices (n_free,) of the DOFs not in ``prescribed``; raises on out-of-range or repeats."""
    prescribed = np.asarray(prescribed, dtype=np.int64)
    if prescribed.size and (prescribed.min() < 0 or prescribed.max() >= n_dofs):
        raise ValueError(f"prescribed DOF indices must lie in [0, {n_dofs})")
    if np.unique(prescribed).size != prescribed.size:
        raise ValueError("prescribed DOF indices contain duplicates")
    mask = np.ones(n_dofs, dtype=bool)
    mask[prescribed] = False
    return np.flatnonzero(mask)


def solve_static(
    K: sp.spmatrix,
    prescribed: np.ndarray,
    values: np.ndarray,
    f: np.ndarray | None = None,
    solver: str = "auto",
) -> np.ndarray:
    """Solve K d = f with d[prescribed] = values: K_uu d_u = f_u - K_uc d_c.

    K (n, n) N/m; prescribed (n_c,) DOF indices; values (n_c,) m; f (n,) N or None.
    Returns d (n,) in m.
    """
    n = K.shape[0]
    free = free_dofs(n, prescribed)
    K = sp.csr_matrix(K)
    d = np.zeros(n)
    d[prescribed] = values
    rhs = -(K[free][:, prescribed] @ np.asarray(values, dtype=np.float64))
    if f is not None:
        rhs += f[free]
    d[free] = factorize(K[free][:, free], solver)(rhs)
    return d


def reactions(K: sp.spmatrix, d: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
    """Reaction forces (n,) N = K d - f; nonzero only at prescribed DOFs of an equilibrium d."""
    r = K @ d
    return r if f is None else r - f
