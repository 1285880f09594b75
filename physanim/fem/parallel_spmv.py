"""Multithreaded CSR matrix-vector products for the per-step FEM right-hand sides.

scipy's ``csr_matrix @ x`` runs on one core; a Newmark step multiplies ~1.6M stored entries
per step, memory-bound, so splitting the rows over the cores (balanced by stored entries)
nearly halves it on two cores. The quadratic form x^T A x of a symmetric A reads only its
upper triangle (half the bytes) and makes no BLAS call: numpy's threaded BLAS stalled for
milliseconds right after a numba parallel region here (both thread pools spinning on two
cores).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from physanim.fem.numba_threads import work_partitions  # sets the threading layer first

# unsigned offsets and indices (uint64 / uint32): numba adds a negative-index wraparound
# select to every load through a signed index
_U1, _U2 = np.uint64(1), np.uint64(2)


@njit(cache=True, inline="always")
def _row_dot(indptr, indices, data, x, i):
    acc0 = 0.0
    acc1 = 0.0
    k, end = indptr[i], indptr[i + 1]
    while k + _U1 < end:
        acc0 += data[k] * x[indices[k]]
        acc1 += data[k + _U1] * x[indices[k + _U1]]
        k += _U2
    if k < end:
        acc0 += data[k] * x[indices[k]]
    return acc0 + acc1


@njit(cache=True)
def _rows(indptr, indices, data, x, lo, hi, out):
    for i in range(lo, hi):
        out[i] = _row_dot(indptr, indices, data, x, i)


@njit(cache=True)
def _rows_quad(indptr, indices, data, x, lo, hi):
    acc = 0.0
    for i in range(lo, hi):
        acc += x[i] * _row_dot(indptr, indices, data, x, i)
    return acc


# the row loops live in their own functions: compiled inside a prange body they ran 2x slower
@njit(cache=True, parallel=True)
def _matvec(indptr, indices, data, x, bounds, out):
    for t in prange(bounds.size - 1):
        _rows(indptr, indices, data, x, bounds[t], bounds[t + 1], out)


@njit(cache=True, parallel=True)
def _quadratic_form(indptr, indices, data, x, bounds):
    parts = np.zeros(bounds.size - 1)
    for t in prange(bounds.size - 1):
        parts[t] = _rows_quad(indptr, indices, data, x, bounds[t], bounds[t + 1])
    return parts.sum()


def _csr_arrays(A: sp.spmatrix, n_threads: int | None) -> tuple[np.ndarray, ...]:
    """indptr (uint64), indices (uint32), data and per-thread row bounds (k + 1,) of A.

    Duplicates summed, stored zeros dropped (e.g. the consistent mass stores 3x3 blocks that
    are m_ij I); the row ranges hold equal numbers of entries.
    """
    A = sp.csr_matrix(A, copy=True)
    A.sum_duplicates()
    A.eliminate_zeros()
    k = work_partitions(n_threads)
    cuts = np.searchsorted(A.indptr, A.nnz * np.arange(1, k) / k)
    bounds = np.r_[0, cuts, A.shape[0]].astype(np.int64)
    return A.indptr.astype(np.uint64), A.indices.astype(np.uint32), A.data, bounds


class ParallelCSR:
    """y = A x for a fixed sparse A (n, m) in ``n_threads`` row pieces (default: numba's thread
    pool size, :func:`~physanim.fem.numba_threads.work_partitions`), run on numba's threads."""

    def __init__(self, A: sp.spmatrix, n_threads: int | None = None) -> None:
        self.shape = A.shape
        self.indptr, self.indices, self.data, self.bounds = _csr_arrays(A, n_threads)

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        """A @ x for x (m,) or (m, k) float64; returns (n,) or (n, k)."""
        x = np.asarray(x, np.float64)
        if x.ndim == 2:
            return np.column_stack([self @ x[:, j] for j in range(x.shape[1])])
        out = np.empty(self.shape[0])
        _matvec(self.indptr, self.indices, self.data, np.ascontiguousarray(x), self.bounds, out)
        return out


class SymmetricQuadraticForm:
    """x^T A x for a fixed symmetric sparse A (n, n), from its upper triangle, on all threads.

    Stores U = triu(A) with the off-diagonal entries doubled, so x^T A x = sum_i x_i (U x)_i.
    """

    def __init__(self, A: sp.spmatrix, n_threads: int | None = None) -> None:
        A = sp.csr_matrix(A)
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"quadratic form needs a square matrix, got {A.shape}")
        U = sp.triu(A, 1, format="csr") * 2.0 + sp.diags(A.diagonal())
        self.n = A.shape[0]
        self.indptr, self.indices, self.data, self.bounds = _csr_arrays(U, n_threads)

    def __call__(self, x: np.ndarray) -> float:
        """x^T A x for x (n,) float64."""
        x = np.asarray(x, np.float64)
        return float(_quadratic_form(self.indptr, self.indices, self.data, x, self.bounds))
