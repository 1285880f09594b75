"""Factorise a constant sparse SPD matrix once and solve many right-hand sides."""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import cache
from importlib.util import find_spec
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from physanim.fem.parallel_ldl import ParallelLDL
from physanim.fem.pardiso import PardisoFactors, has_pardiso

Solve = Callable[[np.ndarray], np.ndarray]
SOLVERS = ("auto", "pardiso", "cholmod", "superlu", "superlu_colamd")


def has_cholmod() -> bool:
    """True when scikit-sparse (CHOLMOD) is importable."""
    return find_spec("sksparse") is not None


def dynamic_solver(solver: str) -> str:
    """The solver 'auto' means for the Newmark matrix: PARDISO (MKL) when it loads, else
    CHOLMOD when installed, else SuperLU; any other name unchanged."""
    if solver != "auto":
        return solver
    return "pardiso" if has_pardiso() else "cholmod" if has_cholmod() else "superlu"


def without_subnormals(solve: Solve, n: int, floor: float = 1e-100) -> Solve:
    """Wrap ``solve`` so that its triangular sweeps never meet subnormal numbers.

    A localised right-hand side (a few driven nodes) gives a solution that decays
    exponentially away from them; its far field underflows to subnormals, which make the
    sweeps ~3x slower on x86. Solving for b + r with a fixed r = 1e-100 and subtracting
    x_r = A^-1 r keeps every intermediate far above the subnormal range; the change to x is
    of order 1e-100 relative to A^-1, far below round-off of any physical answer. ``floor``:
    r's entries (``subnormal_floor``).
    """
    r = np.full(n, floor)
    x_r = solve(r)

    def guarded(b: np.ndarray) -> np.ndarray:
        if b.ndim == 1:
            return solve(b + r) - x_r
        return solve(b + r[:, None]) - x_r[:, None]

    return guarded


def subnormal_floor(factors: object) -> float:
    """``without_subnormals``' r for solves by ``factors``: 1e-20 where PARDISO sweeps in
    float32 (its subnormals start at 1e-38), else 1e-100 (float64 sweeps)."""
    single = isinstance(factors, PardisoFactors) and np.dtype(factors.dtype) == np.float32
    return 1e-20 if single else 1e-100


def _require_cholmod() -> None:
    if not has_cholmod():
        raise ModuleNotFoundError(
            "solver 'cholmod' needs scikit-sparse: apt-get install libsuitesparse-dev, then "
            "pip install 'scikit-sparse<0.5' (or choose solver 'superlu')"
        )


@cache
def blas_in_use() -> str:
    """The BLAS library CHOLMOD calls in this process, e.g. 'OpenBLAS' or 'reference BLAS
    (slow)', with its path; read from the process's memory map once CHOLMOD is loaded."""
    if not has_cholmod():
        return "none (no CHOLMOD)"
    import sksparse.cholmod  # noqa: F401  (maps libcholmod and its BLAS)

    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "/" in line}
    except OSError:
        return "unknown (no /proc/self/maps)"
    names = {os.path.basename(p): p for p in sorted(paths) if "site-packages" not in p}
    for lib, label in (("libmkl_rt", "MKL"), ("libblis", "BLIS"), ("libopenblas", "OpenBLAS")):
        hit = [p for n, p in names.items() if n.startswith(lib)]
        if hit:
            return f"{label} ({hit[0]})"
    blas = [p for n, p in names.items() if n.startswith("libblas.so")]
    if blas and "atlas" in blas[0]:
        return f"ATLAS ({blas[0]})"
    if blas:
        return f"reference BLAS (slow; {blas[0]})"
    return "unknown"


def optimized_blas() -> bool:
    """True when CHOLMOD runs on an optimised BLAS (its supernodal factorisation is BLAS-3)."""
    return not blas_in_use().startswith(("reference", "none", "unknown"))


class CholmodFactors:
    """Factorises a series of matrices with one sparsity pattern (a Newmark matrix at
    several time steps): CHOLMOD's METIS ordering and symbolic analysis once, then per matrix
    a numeric factorisation, solved by a ``ParallelLDL`` that reuses the first one's tree
    partition and supernode blocks.

    mode 'supernodal': SPD matrices, LL^T by BLAS-3 supernodes (fast with an optimised BLAS);
    'simplicial': LDL^T, also for quasi-definite matrices. dtype: precision of the stored
    factor (float32 halves the bytes each solve reads).
    """

    def __init__(self, mode: str = "supernodal", dtype: type = np.float64) -> None:
        _require_cholmod()
        self.mode, self.dtype = mode, dtype
        self._symbolic: Any = None
        self._ldl: ParallelLDL | None = None
        self.factor_entries = 0  # entries of the last factor's L

    def __call__(self, A: sp.spmatrix) -> ParallelLDL:
        """Solver of A (n, n), which must have the pattern of the first matrix given."""
        from sksparse.cholmod import analyze

        A = sp.csc_matrix(A)
        if self._symbolic is None:
            try:
                self._symbolic = analyze(A, mode=self.mode, ordering_method="metis")
            except Exception:  # a CHOLMOD built without METIS  # noqa: BLE001
                self._symbolic = analyze(A, mode=self.mode, ordering_method="amd")
        factor = self._symbolic.cholesky(A)
        if self.mode == "supernodal":
            L = factor.L()
            self.factor_entries = int(L.nnz)
            if self._ldl is None:
                self._ldl = ParallelLDL.from_cholesky(L, factor.P(), dtype=self.dtype)
                return self._ldl
            return self._ldl.refilled_cholesky(L)
        L, D = factor.L_D()
        self.factor_entries = int(L.nnz)
        d = D.diagonal()
        if self._ldl is not None:
            try:
                return self._ldl.refilled(L, d)
            except ValueError:  # the numeric factorisation changed the pattern
                pass
        self._ldl = ParallelLDL(L, d, factor.P(), dtype=self.dtype)
        return self._ldl


def factorize(A: sp.spmatrix, solver: str = "auto") -> Solve:
    """Factorise the SPD matrix ``A`` (n, n) and return ``solve(b) -> x`` for b (n,) or (n, k).

    solver: 'cholmod' (CHOLMOD's METIS ordering and supernodal LL^T factor, solved by
    ``ParallelLDL`` on all threads; A must be positive definite), 'pardiso' (MKL PARDISO's
    METIS ordering and supernodal LL^T, float64), 'superlu' (SuperLU with
    MMD(A^T+A) ordering and symmetric pivoting, right for SPD matrices), 'superlu_colamd'
    (scipy's default splu, the baseline) or 'auto' (cholmod when installed, else superlu).
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if solver == "auto":
        solver = "cholmod" if has_cholmod() else "superlu"
    if solver == "cholmod":
        return without_subnormals(CholmodFactors("supernodal")(A), A.shape[0])
    if solver == "pardiso":
        return without_subnormals(PardisoFactors("spd")(A), A.shape[0])
    if solver == "superlu":
        lu = spla.splu(
            sp.csc_matrix(A),
            permc_spec="MMD_AT_PLUS_A",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
    else:
        lu = spla.splu(sp.csc_matrix(A))
    return without_subnormals(lu.solve, A.shape[0])


class SymmetricFactors:
    """Factorises a series of symmetric matrices with one sparsity pattern that may be
    indefinite (large-strain tangents away from equilibrium): with MKL, PARDISO's LL^T
    (its ordering and analysis once per pattern) where the matrix is positive definite, its
    LDL^T with Bunch-Kaufman pivots where it is not; without MKL, SuperLU's LU.

    Why not LDL^T always: PARDISO's indefinite solves of many right-hand sides run an order
    slower (the demo's tangent, 16,725 free DOFs, 1,835 columns, 2 cores: 45 s against 4 s;
    one column 8 ms either way). Its factorisation takes 0.3-0.5 s there, SuperLU's 4.0 s;
    an indefinite matrix costs the refused LL^T's attempt besides.
    """

    def __init__(self) -> None:
        self._factors: dict[str, PardisoFactors] = {}

    def __call__(self, A: sp.spmatrix) -> Solve:
        """Solver of the symmetric A (n, n)."""
        if not has_pardiso():
            return factorize(A, "superlu")
        try:
            solve = self._pardiso("spd", A)
        except RuntimeError:  # a pivot that is not positive: indefinite
            solve = self._pardiso("indefinite", A)
        return without_subnormals(solve, A.shape[0])

    def _pardiso(self, kind: str, A: sp.spmatrix) -> Solve:
        """PARDISO's factor of A as ``kind``, with its pattern's analysis (made on first use)."""
        factors = self._factors.get(kind)
        if factors is not None:
            try:
                return factors(A)
            except ValueError:  # another pattern
                pass
        self._factors[kind] = PardisoFactors(kind)
        return self._factors[kind](A)


def factorize_many(A: sp.spmatrix, solver: str = "auto") -> Solve:
    """Like :func:`factorize`, for blocks of many right-hand sides (n, k); 'auto' as
    :func:`dynamic_solver`. PARDISO and CHOLMOD solve a block by BLAS-3 supernodes (the demo's
    static K_uu at 6 mm patches, 128 columns: PARDISO 1.0 ms a column, CHOLMOD's own solve
    1.8 ms, ``ParallelLDL``'s sweeps, which suit one or two columns, 9 ms)."""
    if solver == "auto":
        solver = dynamic_solver(solver)
    if solver != "cholmod":
        return factorize(A, solver)
    _require_cholmod()
    from sksparse.cholmod import cholesky

    A = sp.csc_matrix(A)
    try:
        factor = cholesky(A, ordering_method="metis")
    except Exception:  # a CHOLMOD built without METIS  # noqa: BLE001
        factor = cholesky(A, ordering_method="amd")
    return without_subnormals(factor, A.shape[0])


def factorize_split(
    A_el: sp.spmatrix,
    G: sp.spmatrix,
    w: np.ndarray,
    solver: str = "auto",
    factors: CholmodFactors | PardisoFactors | None = None,
) -> Solve:
    """Solver for A = A_el + G^T diag(w) G (n, n) without forming the product.

    A_el (n, n) SPD, G (k, n), w (k,) > 0. With CHOLMOD or PARDISO this factorises the
    quasi-definite matrix [[A_el, G^T], [G, -diag(1/w)]] by sparse LDL^T (stable for
    quasi-definite matrices under any symmetric ordering): G^T diag(w) G couples two rings of
    nodes and fills the Cholesky factor, the augmented matrix only one ring. Other solvers
    factorise A directly. ``factors``: a simplicial ``CholmodFactors`` or an 'indefinite'
    ``PardisoFactors`` to reuse across calls with one pattern (its dtype sets the precision).
    """
    if solver == "auto":
        solver = "cholmod" if has_cholmod() else "superlu"
    if solver not in ("cholmod", "pardiso"):
        return factorize((A_el + G.T @ sp.diags(w) @ G).tocsc(), solver)
    n = A_el.shape[0]
    augmented = sp.bmat([[A_el, G.T], [G, sp.diags(-1.0 / w)]], format="csc")
    if factors is None:
        factors = (
            CholmodFactors("simplicial") if solver == "cholmod" else PardisoFactors("indefinite")
        )
    factor = factors(augmented)
    if isinstance(factors, PardisoFactors) and factor.inertia[1] != G.shape[0]:
        raise ValueError(
            f"the augmented matrix is not quasi-definite ({factor.inertia[1]} negative pivots "
            f"for {G.shape[0]} constraint rows): A_el is not positive definite"
        )

    def solve(b: np.ndarray) -> np.ndarray:
        rhs = np.zeros((augmented.shape[0],) + b.shape[1:])
        rhs[:n] = b
        return factor(rhs)[:n]

    return without_subnormals(solve, n, subnormal_floor(factors))
