"""Factorise a constant sparse SPD matrix once and solve many right-hand sides."""

from __future__ import annotations

from collections.abc import Callable
from importlib.util import find_spec

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from physanim.fem.parallel_ldl import ParallelLDL

Solve = Callable[[np.ndarray], np.ndarray]
SOLVERS = ("auto", "cholmod", "superlu", "superlu_colamd")


def has_cholmod() -> bool:
    """True when scikit-sparse (CHOLMOD) is importable."""
    return find_spec("sksparse") is not None


def _without_subnormals(solve: Solve, n: int) -> Solve:
    """Wrap ``solve`` so that its triangular sweeps never meet subnormal numbers.

    A localised right-hand side (a few driven nodes) gives a solution that decays
    exponentially away from them; its far field underflows to subnormals, which make the
    sweeps ~3x slower on x86. Solving for b + r with a fixed r = 1e-100 and subtracting
    x_r = A^-1 r keeps every intermediate far above the subnormal range; the change to x is
    of order 1e-100 relative to A^-1, far below round-off of any physical answer.
    """
    r = np.full(n, 1e-100)
    x_r = solve(r)

    def guarded(b: np.ndarray) -> np.ndarray:
        if b.ndim == 1:
            return solve(b + r) - x_r
        return solve(b + r[:, None]) - x_r[:, None]

    return guarded


def _cholmod_ldl(A: sp.csc_matrix) -> ParallelLDL:
    """CHOLMOD's fill-reducing ordering and simplicial LDL^T of A, solved on all threads."""
    if not has_cholmod():
        raise ModuleNotFoundError(
            "solver 'cholmod' needs scikit-sparse: apt-get install libsuitesparse-dev, then "
            "pip install 'scikit-sparse<0.5' (or choose solver 'superlu')"
        )
    from sksparse.cholmod import cholesky

    # 'best' tries AMD, METIS and nested dissection and keeps the sparsest factor
    factor = cholesky(A, mode="simplicial", ordering_method="best")
    L, D = factor.L_D()
    return ParallelLDL(L, D.diagonal(), factor.P())


def factorize(A: sp.spmatrix, solver: str = "auto") -> Solve:
    """Factorise the SPD matrix ``A`` (n, n) and return ``solve(b) -> x`` for b (n,) or (n, k).

    solver: 'cholmod' (CHOLMOD's fill-reducing ordering and LDL^T factor, solved by
    ``ParallelLDL`` on all threads), 'superlu' (SuperLU with MMD(A^T+A) ordering and symmetric
    pivoting, right for SPD matrices), 'superlu_colamd' (scipy's default splu, the baseline)
    or 'auto' (cholmod when installed, else superlu).
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if solver == "auto":
        solver = "cholmod" if has_cholmod() else "superlu"
    if solver == "cholmod":
        return _without_subnormals(_cholmod_ldl(sp.csc_matrix(A)), A.shape[0])
    if solver == "superlu":
        lu = spla.splu(
            sp.csc_matrix(A),
            permc_spec="MMD_AT_PLUS_A",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
    else:
        lu = spla.splu(sp.csc_matrix(A))
    return _without_subnormals(lu.solve, A.shape[0])


def factorize_split(
    A_el: sp.spmatrix, G: sp.spmatrix, w: np.ndarray, solver: str = "auto"
) -> Solve:
    """Solver for A = A_el + G^T diag(w) G (n, n) without forming the product.

    A_el (n, n) SPD, G (k, n), w (k,) > 0. With CHOLMOD this factorises the quasi-definite
    matrix [[A_el, G^T], [G, -diag(1/w)]] by sparse LDL^T (stable for quasi-definite matrices
    under any symmetric ordering): G^T diag(w) G couples two rings of nodes and fills the
    Cholesky factor, the augmented matrix only one ring. Other solvers factorise A directly.
    """
    if solver == "auto":
        solver = "cholmod" if has_cholmod() else "superlu"
    if solver != "cholmod":
        return factorize((A_el + G.T @ sp.diags(w) @ G).tocsc(), solver)
    n = A_el.shape[0]
    factor = _cholmod_ldl(sp.bmat([[A_el, G.T], [G, sp.diags(-1.0 / w)]], format="csc"))

    def solve(b: np.ndarray) -> np.ndarray:
        rhs = np.zeros((factor.n,) + b.shape[1:])
        rhs[:n] = b
        return factor(rhs)[:n]

    return _without_subnormals(solve, n)
