"""Intel MKL PARDISO through ctypes: supernodal, multithreaded LDL^T of a sparse symmetric
matrix (positive definite, or quasi-definite such as the 'anp' augmented matrix), its factor
stored in single or double precision.

Why our own binding: pypardiso, the PyPI wrapper, takes float64 matrices only and fixes the
options. The FEM needs PARDISO's single-precision factor (iparm[27]) and its symmetric
indefinite mode (mtype -2) for [[A_el, G^T], [G, -diag(1/w)]]: CHOLMOD's supernodal factor is
LL^T only, so it must factorise A_el + G^T diag(w) G, whose two-ring coupling doubles the
factor (2 mm demo mesh: 125M against 64M entries), and its simplicial LDL^T of the augmented
matrix is single-threaded (45 s there against PARDISO's 1.6 s, 1.0 s in single precision).

The runtime is the ``mkl`` wheel's ``libmkl_rt``; without it ``has_pardiso()`` is False and
the FEM falls back to CHOLMOD. MKL threads through GNU OpenMP (libgomp), the runtime numba's
parallel kernels use, unless MKL_THREADING_LAYER says otherwise.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import glob
import os
import sys
import threading
import weakref
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from physanim.fem.numba_threads import work_partitions

# the options (iparm, 0-based as in MKL's C reference) this binding sets; all others 0
_IPARM = {
    0: 1,  # not the defaults: the entries below
    1: 3,  # METIS nested-dissection ordering, its OpenMP version (2 mm demo: 0.2 s of 0.9 s less)
    7: 0,  # iterative refinement only where pivots were perturbed (two steps)
    9: 8,  # pivots perturbed by 1e-8 ||A|| (symmetric indefinite)
    17: -1,  # report the factor's entries
    20: 1,  # Bunch-Kaufman 1x1 and 2x2 pivots (symmetric indefinite)
    23: 1,  # two-level parallel factorisation
    34: 1,  # zero-based ia, ja
}
_MESSAGES = {
    -1: "input inconsistent",
    -2: "not enough memory",
    -3: "reordering problem",
    -4: "zero pivot or a matrix that is not positive definite",
    -7: "diagonal matrix is singular",
    -8: "32-bit integer overflow",
    -10: "error opening the out-of-core files",
}
SPD, INDEFINITE = 2, -2  # PARDISO's matrix types (real symmetric)


@functools.cache
def mkl_runtime() -> ctypes.CDLL | None:
    """MKL's single dynamic library (``mkl`` wheel or system), or None when absent."""
    paths = sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")), key=len)
    found = ctypes.util.find_library("mkl_rt")
    for path in [*paths, *([found] if found else [])]:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        if "MKL_THREADING_LAYER" not in os.environ and ctypes.util.find_library("gomp"):
            lib.MKL_Set_Threading_Layer(ctypes.c_int(3))  # MKL_THREADING_GNU
        lib.pardiso.restype = None
        return lib
    return None


def has_pardiso() -> bool:
    """True when MKL PARDISO can be loaded."""
    return mkl_runtime() is not None


class _Handle:
    """One PARDISO instance: the symbolic analysis of a pattern (upper triangle, CSR) and up
    to ``slots`` numeric factors of matrices with that pattern."""

    def __init__(self, upper: sp.csr_matrix, mtype: int, dtype: type, slots: int) -> None:
        lib = mkl_runtime()
        if lib is None:
            raise RuntimeError("solver 'pardiso' needs MKL: pip install mkl")
        self.lib, self.mtype, self.dtype, self.slots = lib, mtype, np.dtype(dtype), slots
        self.n = upper.shape[0]
        self.indptr = upper.indptr.astype(np.int32)
        self.indices = upper.indices.astype(np.int32)
        self.pt = np.zeros(64, np.int64)
        self.iparm = np.zeros(64, np.int32)
        for i, v in _IPARM.items():
            self.iparm[i] = v
        self.iparm[27] = 1 if self.dtype == np.float32 else 0
        self.free = list(range(slots, 0, -1))
        self.lock = threading.RLock()  # a solver dropped (finalised) mid-call frees its slot
        self.factor_entries = int(self.call(11, 1, upper.data.astype(self.dtype))[17])
        weakref.finalize(self, _release_all, lib, self.pt, self.iparm, mtype, slots, self.n)

    def call(self, phase: int, mnum: int, a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
        """One PARDISO call; b (n, k) Fortran-ordered, solved in place (phase 33). Returns
        the call's iparm (64,), read before another thread's call can change it."""
        x = np.empty_like(b) if b is not None else None
        with self.lock:
            # always numba's pool size, whatever count numba runs on now or threadpoolctl set
            # for MKL's BLAS: PARDISO's factor and sweeps, and so its results, depend on it
            before = self.lib.MKL_Set_Num_Threads_Local(ctypes.c_int(work_partitions()))
            err = _pardiso(self.lib, self.pt, self.iparm, self.slots, mnum, self.mtype, phase,
                           self.n, a, self.indptr, self.indices, b, x)  # fmt: skip
            self.lib.MKL_Set_Num_Threads_Local(ctypes.c_int(before))
            iparm = self.iparm.copy()
        if err:
            why = _MESSAGES.get(err, "see MKL's PARDISO error codes")
            raise RuntimeError(f"PARDISO phase {phase}: error {err} ({why})")
        if x is not None:
            b[...] = x
        return iparm


def _pardiso(
    lib: ctypes.CDLL,
    pt: np.ndarray,
    iparm: np.ndarray,
    maxfct: int,
    mnum: int,
    mtype: int,
    phase: int,
    n: int,
    a: np.ndarray | None = None,
    ia: np.ndarray | None = None,
    ja: np.ndarray | None = None,
    b: np.ndarray | None = None,
    x: np.ndarray | None = None,
) -> int:
    """MKL's ``pardiso`` with its scalars by reference (arrays a phase does not read may be
    None). Returns its error code (0: success)."""
    ptr = lambda arr: None if arr is None else arr.ctypes.data_as(ctypes.c_void_p)  # noqa: E731
    i32 = lambda v: ctypes.byref(ctypes.c_int32(v))  # noqa: E731
    nrhs = 1 if b is None or b.ndim == 1 else b.shape[1]
    err = ctypes.c_int32(0)
    lib.pardiso(ptr(pt), i32(maxfct), i32(mnum), i32(mtype), i32(phase), i32(n), ptr(a), ptr(ia),
                ptr(ja), None, i32(nrhs), ptr(iparm), i32(0), ptr(b), ptr(x),
                ctypes.byref(err))  # fmt: skip
    return err.value


def _release_all(lib: ctypes.CDLL, pt: np.ndarray, iparm: np.ndarray, *args: int) -> None:
    """Phase -1: frees every factor and the analysis of a handle (its finaliser)."""
    mtype, slots, n = args
    _pardiso(lib, pt, iparm, slots, 1, mtype, -1, n)


class PardisoSolve:
    """``solve(b) -> x`` with one numeric factor: b (n,) or (n, k), x float64 like b."""

    def __init__(self, handle: _Handle, upper: sp.csr_matrix) -> None:
        if not handle.free:
            raise RuntimeError("no free PARDISO factor slot")
        self.handle, self.n = handle, handle.n
        self.slot = handle.free.pop()
        self.values = upper.data.astype(handle.dtype)  # read again by iterative refinement
        weakref.finalize(self, _release_slot, handle, self.slot)
        iparm = handle.call(22, self.slot, self.values)
        self.inertia = (int(iparm[21]), int(iparm[22]))  # (+, -) pivots

    def __call__(self, b: np.ndarray) -> np.ndarray:
        rhs = np.asfortranarray(b, dtype=self.handle.dtype)
        if rhs is b:
            rhs = rhs.copy(order="F")
        self.handle.call(33, self.slot, self.values, rhs)
        return rhs.astype(np.float64)


def _release_slot(handle: _Handle, slot: int) -> None:
    try:  # phase 0: frees factor ``slot``'s memory, keeps the analysis
        handle.call(0, slot, np.zeros(1, handle.dtype))
    finally:
        handle.free.append(slot)


class PardisoFactors:
    """Factorises a series of matrices with one sparsity pattern (a Newmark matrix at
    several step sizes): METIS ordering and symbolic analysis once, then a numeric factor per
    matrix in its own slot, freed when its solver is dropped.

    kind: 'spd' (positive definite; PARDISO stops on a non-positive pivot) or 'indefinite'
    (symmetric, Bunch-Kaufman pivots: quasi-definite matrices such as [[A, G^T], [G, -D]]).
    dtype: precision of the stored factor (float32 halves the bytes each solve reads; its
    solves are exact for a matrix within float32 round-off of the given one).
    """

    def __init__(self, kind: str = "spd", dtype: type = np.float64, slots: int = 20) -> None:
        if kind not in ("spd", "indefinite"):
            raise ValueError(f"kind must be 'spd' or 'indefinite', got {kind!r}")
        self.mtype = SPD if kind == "spd" else INDEFINITE
        self.dtype, self.slots = dtype, slots
        self._handles: list[_Handle] = []

    def __call__(self, A: sp.spmatrix) -> Callable[[np.ndarray], np.ndarray]:
        """Solver of the symmetric A (n, n); later matrices must share the first's pattern."""
        upper = sp.triu(A, format="csr")
        upper.sort_indices()
        if self._handles and not _same_pattern(self._handles[0], upper):
            raise ValueError("PardisoFactors: the matrix's pattern differs from the first one")
        handle = next((h for h in self._handles if h.free), None)
        if handle is None:
            handle = _Handle(upper, self.mtype, self.dtype, self.slots)
            self._handles.append(handle)
        return PardisoSolve(handle, upper)

    @property
    def factor_entries(self) -> int:
        """Entries of one factor (0 before the first matrix)."""
        return self._handles[0].factor_entries if self._handles else 0


def _same_pattern(handle: _Handle, upper: sp.csr_matrix) -> bool:
    return np.array_equal(handle.indptr, upper.indptr) and np.array_equal(
        handle.indices, upper.indices
    )
