"""Newmark-beta (beta = 1/4, gamma = 1/2) for M d'' + C d' + K d = f with prescribed DOFs.

SPEC eqs 4.27-4.37: A = K + (4/dt^2) M + (2/dt) C,
q = M((4/dt^2) d_t + (4/dt) d'_t + d''_t) + C((2/dt) d_t + d'_t), A d_{t+1} = f_{t+1} + q,
partitioned into unknown (u) and prescribed (c) DOFs: A_uu d_u = f_u + q_u - A_uc d_c.
The prescribed DOFs' velocity and acceleration at t+1 come from their given trajectory
(not from Newmark differencing, which rings at the Nyquist rate where the trajectory's
acceleration jumps); the u rows are then exactly the equation of motion at t+1.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit, prange
from threadpoolctl import threadpool_limits

from physanim.fem.elements import formed
from physanim.fem.linsolve import (
    CholmodFactors,
    Solve,
    dynamic_solver,
    factorize,
    factorize_split,
    optimized_blas,
    subnormal_floor,
    without_subnormals,
)
from physanim.fem.parallel_spmv import ParallelCSR, SymmetricQuadraticForm
from physanim.fem.pardiso import PardisoFactors
from physanim.fem.statics import free_dofs


@dataclass
class State:
    """Displacement d (m), velocity v (m/s) and acceleration a (m/s^2), each (n_dofs,)."""

    d: np.ndarray
    v: np.ndarray
    a: np.ndarray

    @classmethod
    def rest(cls, n_dofs: int) -> State:
        return cls(np.zeros(n_dofs), np.zeros(n_dofs), np.zeros(n_dofs))


class Newmark:
    """Average-acceleration Newmark integrator; A_uu is factorised in the constructor.

    K, M, C: (n, n) sparse, N/m, kg, N s/m. dt: step, s. prescribed: (n_c,) DOF indices.
    solver: 'auto' (``dynamic_solver``: PARDISO, else CHOLMOD, else SuperLU) or a name.
    split: optional (K_el, G, w) with K = K_el + G^T diag(w) G (the 'anp' model), which lets
    PARDISO, and CHOLMOD when its BLAS is the slow reference one, factorise the sparser
    augmented matrix (see ``factorize_split``); with an optimised BLAS CHOLMOD's supernodal
    LL^T of A_uu is faster than its simplicial LDL^T of the augmented one. K may be None
    with a split: formed from it only if the solver needs it (its products take the split).
    precision: 'float64'; 'float32' (PARDISO and CHOLMOD; SuperLU keeps float64): with
    CHOLMOD the factor stored in single precision and swept in float64, each solve exact for
    a matrix within float32 round-off of A_uu, so the steps are Newmark's on a stiffness
    perturbed by ~1e-7 relative; with PARDISO factor and sweeps in single precision, each
    step's right-hand side rounded too (the demo's nodes within 61 nm of float64's, 4e-6 of
    the peak); or 'mixed', a float32 factor with each solve refined once with the float64
    matrix (twice the solves).
    ``with_dt`` makes integrators at other step sizes that share everything but the factor,
    whose symbolic analysis they share too.
    """

    def __init__(
        self,
        K: sp.spmatrix | None,
        M: sp.spmatrix,
        C: sp.spmatrix,
        dt: float,
        prescribed: np.ndarray,
        solver: str = "auto",
        split: tuple[sp.spmatrix, sp.spmatrix, np.ndarray] | None = None,
        precision: str = "float64",
    ) -> None:
        if K is None and split is None:
            raise ValueError("Newmark needs the stiffness K or its split (K_el, G, w)")
        n = M.shape[0]
        self.prescribed = np.asarray(prescribed, dtype=np.int64)
        self.free = free_dofs(n, self.prescribed)
        self._K = None if K is None else sp.csr_matrix(K)
        self.M, self.C = sp.csr_matrix(M), sp.csr_matrix(C)
        self._stiffness_split = None if split is None else (sp.csr_matrix(split[0]), *split[1:])
        self.solver = dynamic_solver(solver)
        if precision not in ("float64", "float32", "mixed"):
            raise ValueError(
                f"precision must be 'float64', 'float32' or 'mixed', got {precision!r}"
            )
        factored = self.solver in ("cholmod", "pardiso")
        if precision == "mixed" and not factored:
            raise ValueError("precision 'mixed' needs solver 'pardiso' or 'cholmod'")
        self.precision = precision if factored else "float64"
        u = self.free
        self._split = None
        if split is not None and (
            self.solver == "pardiso" or (self.solver == "cholmod" and not optimized_blas())
        ):
            K_el, G, w = self._stiffness_split
            self._split = (sp.csr_matrix(G)[:, u], w)
            stiffness = K_el
        else:
            stiffness = self.K
        # A(dt) = K_uu + (4/dt^2) M_uu + (2/dt) C_uu (with the split: A_el, K_el in place of
        # K, and A_uu = A_el + G^T diag(w) G is never formed): values on one pattern
        self._pattern, self._kmc = _free_blocks(u, sp.csr_matrix(stiffness), self.M, self.C)
        self._M_uu = sp.csr_matrix(  # initial accelerations
            (self._kmc[1], self._pattern.indices, self._pattern.indptr), self._pattern.shape
        )
        self._factors: CholmodFactors | PardisoFactors | None = None
        dtype = np.float64 if precision == "float64" else np.float32
        if self.solver == "cholmod":
            mode = "supernodal" if self._split is None else "simplicial"
            self._factors = CholmodFactors(mode, dtype)
        elif self.solver == "pardiso":
            self._factors = PardisoFactors("spd" if self._split is None else "indefinite", dtype)
        # rhs_u = [M_u: | C_u: | K_uc] @ [x_m; x_c; -d_c] in a single sparse product
        M_u, C_u = self.M[u], self.C[u]
        self._H = ParallelCSR(_side_by_side(M_u, C_u, self._K_block(u)))
        self._x = np.zeros(self._H.shape[1])
        # the error's right-hand side: [M_u: | C_uc] @ [x_m; x_c on the prescribed DOFs], a
        # quarter of H's stored entries (its C_u: block is the largest, the mass's 3x3
        # blocks store only their diagonals)
        self._E = ParallelCSR(_side_by_side(M_u, C_u[:, self.prescribed]))
        self._dissipation_form = SymmetricQuadraticForm(self.C)
        self._set_dt(dt)

    @property
    def K(self) -> sp.csr_matrix:
        """The stiffness (n, n) N/m; formed from the split on first use if not given."""
        if self._K is None:
            self._K = formed(*self._stiffness_split)
        return self._K

    def _K_block(self, rows: np.ndarray) -> sp.csr_matrix:
        """K[rows][:, prescribed], from the split when there is one (K_el's rows hold one
        ring of nodes, K's two)."""
        c = self.prescribed
        if self._stiffness_split is None:
            return self.K[rows][:, c]
        K_el, G, w = self._stiffness_split
        G = sp.csc_matrix(G)
        return (K_el[rows][:, c] + G[:, rows].T @ sp.diags(w) @ G[:, c]).tocsr()

    def _K_times(self, d: np.ndarray) -> np.ndarray:
        """K d (n,) N for d (n,) m, from the split when there is one."""
        if self._stiffness_split is None:
            return self.K @ d
        K_el, G, w = self._stiffness_split
        return K_el @ d + G.T @ (w * (G @ d))

    def _set_dt(self, dt: float) -> None:
        self.dt = float(dt)
        c0, c1 = 4.0 / self.dt**2, 2.0 / self.dt
        k, m, c = self._kmc
        self._A = self._pattern.copy()
        self._A.data = k + c0 * m + c1 * c
        if self._factors is None:
            self.solve: Solve = factorize(self._A, self.solver)
            return
        if self._split is not None:
            G, w = self._split
            solve = factorize_split(self._A, G, w, self.solver, self._factors)
        else:
            solve = without_subnormals(
                self._factors(self._A), self._A.shape[0], subnormal_floor(self._factors)
            )
        if self.precision == "mixed":
            solve = _refined(solve, ParallelCSR(self.A_uu))
        self.solve = solve

    @property
    def factor_entries(self) -> int:
        """Entries of the factor's L (PARDISO, CHOLMOD; 0 for SuperLU, not counted)."""
        return getattr(self._factors, "factor_entries", 0)

    @property
    def A_uu(self) -> sp.csc_matrix:
        """The step's matrix K_uu + (4/dt^2) M_uu + (2/dt) C_uu (n_free, n_free); with the
        split it is formed here, from A_el + G^T diag(w) G."""
        if self._split is None:
            return self._A
        G, w = self._split
        return (self._A + G.T @ sp.diags(w) @ G).tocsc()

    def with_dt(self, dt: float) -> Newmark:
        """This integrator at step ``dt`` (s): shares the matrices, products and symbolic
        analysis; only the numeric factorisation is new."""
        out = copy.copy(self)
        out._set_dt(dt)
        return out

    def initial_acceleration(self, state: State, f: np.ndarray | None = None) -> np.ndarray:
        """Free-DOF accelerations from M a = f - K d - C v (prescribed ones kept); in place."""
        u = self.free
        r = (
            -(self._K_times(state.d) + self.C @ state.v)
            - self.M[:, self.prescribed] @ state.a[self.prescribed]
        )
        if f is not None:
            r += f
        state.a[u] = _solve_mass(self._M_uu, r[u])
        return state.a

    def dissipation(self, delta: np.ndarray) -> float:
        """Viscous energy (J) dissipated over the last step, delta = d_{t+1} - d_t (n,) m.

        Exact for this scheme: the mid-step velocity is delta / dt.
        """
        return self._dissipation_form(delta) / self.dt

    def local_error_rhs(self, delta_a: np.ndarray, defect_c: np.ndarray) -> np.ndarray:
        """The right-hand side (n_free,) whose solve is the estimated displacement error
        (n_free,) m of steps over which the free DOFs' accelerations changed by ``delta_a``
        (n_free,) m/s^2 in all and the prescribed DOFs' paths left the trapezoidal rule by
        ``defect_c`` (n_c,) m (``BoundaryConditions.drive_defect``).

        Zienkiewicz & Xie's estimate for Newmark, e = -(beta - 1/6) h^2 Delta a = -h^2/12
        Delta a, taken through this step's matrix as -(1/3) A_uu^-1 M_uu Delta a: the same for
        motions the step resolves (A_uu ~ 4 M_uu / h^2), while stiff modes, whose
        accelerations ring from step to step with displacements ~ a / omega^2, count at their
        true, tiny size (A_uu ~ K_uu) instead of (omega h)^2 times it. The drive's own
        defect (-h^2/12 Delta a_c on a smooth path, but it also sees motion inside a step
        that the end points miss) acts through the inertial and viscous coupling
        (4/h^2) M_uc + (2/h) C_uc; through K_uc the free DOFs follow the exact end points.
        """
        n, c, h = self.M.shape[0], self.prescribed, self.dt
        x = np.zeros(self._E.shape[1])
        x[self.free] = -delta_a / 3.0
        x[c] = (4.0 / h**2) * defect_c
        x[n:] = (2.0 / h) * defect_c
        return self._E @ x

    def step(
        self,
        state: State,
        d_c: np.ndarray,
        v_c: np.ndarray,
        a_c: np.ndarray,
        f_u: np.ndarray | None = None,
    ) -> State:
        """Advance ``state`` (in place) by dt with prescribed d_c, v_c, a_c (n_c,) at t + dt."""
        d_u = self.solve(self.step_rhs(state, d_c, v_c, a_c, f_u))
        return self.finish_step(state, d_u, d_c, v_c, a_c)

    def step_rhs(
        self,
        state: State,
        d_c: np.ndarray,
        v_c: np.ndarray,
        a_c: np.ndarray,
        f_u: np.ndarray | None = None,
    ) -> np.ndarray:
        """The right-hand side (n_free,) of ``step`` from ``state`` (not modified)."""
        x = self._x
        _pack_rhs(state.d, state.v, state.a, self.free, self.prescribed, d_c, v_c, a_c, self.dt, x)
        rhs = self._H @ x
        if f_u is not None:
            rhs += f_u
        return rhs

    def finish_step(
        self, state: State, d_u: np.ndarray, d_c: np.ndarray, v_c: np.ndarray, a_c: np.ndarray
    ) -> State:
        """``step``'s update of ``state`` (in place) given its solve d_u (n_free,) m."""
        _advance(state.d, state.v, state.a, self.free, d_u, self.dt)
        state.d[self.prescribed], state.v[self.prescribed] = d_c, v_c
        state.a[self.prescribed] = a_c
        return state


# The per-step vector updates as two compiled loops: as numpy expressions over the free
# DOFs they were a dozen gathers and temporaries, ~1 ms of a ~10 ms step.
@njit(cache=True)
def _pack_rhs(d, v, a, u, c, d_c, v_c, a_c, dt, x):
    """x = [x_m; x_c; -d_c] with x_m = (4/dt^2) d + (4/dt) v + a, x_c = (2/dt) d + v on u."""
    n = d.size
    for i in u:
        x[i] = (4.0 / dt**2) * d[i] + (4.0 / dt) * v[i] + a[i]
        x[n + i] = (2.0 / dt) * d[i] + v[i]
    for k in range(c.size):
        x[c[k]] = -a_c[k]
        x[n + c[k]] = -v_c[k]
        x[2 * n + k] = -d_c[k]


@njit(cache=True)
def _advance(d, v, a, u, d_u, dt):
    """Newmark update of the free DOFs u given their new displacements d_u."""
    for k in range(u.size):
        i = u[k]
        a_new = (4.0 / dt**2) * (d_u[k] - d[i]) - (4.0 / dt) * v[i] - a[i]
        v[i] += 0.5 * dt * (a[i] + a_new)
        a[i] = a_new
        d[i] = d_u[k]


def _free_blocks(u: np.ndarray, *mats: sp.csr_matrix) -> tuple[sp.csc_matrix, list[np.ndarray]]:
    """:func:`_common_pattern` of the blocks X[u][:, u] (``u`` sorted) of symmetric CSR
    matrices. When they share one pattern (K_el, M and C assembled on one mesh) the block is
    cut once, from the entries' numbers, and picks every matrix's values (three cuts took
    0.3 s and their merge 0.4 s on a 2 mm demo mesh)."""
    first = mats[0]
    shared = all(
        X.shape == first.shape
        and X.has_canonical_format
        and np.array_equal(X.indptr, first.indptr)
        and np.array_equal(X.indices, first.indices)
        for X in mats
    )
    if not shared:
        return _common_pattern(*(X[u][:, u] for X in mats))
    numbers = sp.csr_matrix(
        (np.arange(1.0, first.nnz + 1), first.indices, first.indptr), shape=first.shape
    )[u][:, u]
    numbers.sort_indices()
    pick = numbers.data.astype(np.int64) - 1
    pattern = sp.csc_matrix(
        (np.ones(len(pick)), numbers.indices, numbers.indptr), shape=numbers.shape
    )
    return pattern, [X.data[pick] for X in mats]


def _side_by_side(*mats: sp.csr_matrix) -> sp.csr_matrix:
    """[A | B | ...] of CSR matrices with the same rows, each row's entries in their order
    (scipy's hstack goes through COO: 0.4 s for the step's right-hand-side operator on a
    2 mm demo mesh)."""
    n = mats[0].shape[0]
    counts = np.stack([np.diff(X.indptr) for X in mats])  # (k, n) entries per row
    indptr = np.r_[0, np.cumsum(counts.sum(axis=0))]
    indices, data = np.empty(indptr[-1], np.int64), np.empty(indptr[-1])
    at, offset = indptr[:-1].copy(), 0  # where each row's next entries go
    for X in mats:
        _append_rows(X.indptr, X.indices, X.data, offset, at, indices, data)
        offset += X.shape[1]
    return sp.csr_matrix((data, indices, indptr), shape=(n, offset))


@njit(cache=True)
def _append_rows(indptr, indices, data, offset, at, out_indices, out_data):
    """Each row's entries of one CSR matrix, columns shifted by ``offset``, written from
    at[row] on (advanced past them)."""
    for i in range(len(indptr) - 1):
        for k in range(indptr[i], indptr[i + 1]):
            out_indices[at[i]] = indices[k] + offset
            out_data[at[i]] = data[k]
            at[i] += 1


def _common_pattern(*mats: sp.csr_matrix) -> tuple[sp.csc_matrix, list[np.ndarray]]:
    """The union sparsity pattern (CSC, sorted; values 1) of symmetric square CSR matrices and
    each one's values on it, so that linear combinations of them are sums of value arrays.

    A symmetric matrix's CSR arrays are its CSC arrays (of its transpose, which it equals):
    the pattern is read that way instead of converted. When one pattern holds all the others
    (M and C lie in K's), it is the union, without building their sum; each matrix's entries
    are placed by one merge of its sorted rows with the pattern's (:func:`_positions`; the
    earlier binary search of int64 keys took 2.3 s on a 2 mm demo mesh, 15M entries)."""
    canonical = []
    for X in mats:
        if not X.has_canonical_format:
            X = X.copy()
            X.sum_duplicates()  # sorted indices, no duplicates
        canonical.append(X)
    pattern = max(canonical, key=lambda X: X.nnz)
    slots = [_positions(pattern.indptr, pattern.indices, X.indptr, X.indices) for X in canonical]
    if any(bool((at < 0).any()) for at in slots):  # no pattern holds the others: their union
        ones = [sp.csr_matrix((np.ones(X.nnz), X.indices, X.indptr), X.shape) for X in canonical]
        pattern = sum(ones[1:], ones[0]).tocsr()
        pattern.sum_duplicates()
        slots = [
            _positions(pattern.indptr, pattern.indices, X.indptr, X.indices) for X in canonical
        ]
    values = []
    for X, at in zip(canonical, slots, strict=True):
        v = np.zeros(pattern.nnz)
        v[at] = X.data
        values.append(v)
    ones = np.ones(pattern.nnz)
    return sp.csc_matrix((ones, pattern.indices, pattern.indptr), shape=pattern.shape), values


@njit(cache=True, parallel=True)
def _positions(
    p_indptr: np.ndarray, p_indices: np.ndarray, x_indptr: np.ndarray, x_indices: np.ndarray
) -> np.ndarray:
    """Where each entry of a CSR matrix X (sorted rows) sits among the entries of the CSR
    pattern P (sorted rows, same shape): (nnz(X),) int64, -1 for an entry P lacks."""
    out = np.empty(len(x_indices), dtype=np.int64)
    for i in prange(len(x_indptr) - 1):
        k, end = p_indptr[i], p_indptr[i + 1]
        for j in range(x_indptr[i], x_indptr[i + 1]):
            c = x_indices[j]
            while k < end and p_indices[k] < c:
                k += 1
            out[j] = k if k < end and p_indices[k] == c else -1
    return out


def _refined(solve: Solve, A: ParallelCSR) -> Solve:
    """One step of iterative refinement: x = S b, then x + S (b - A x) (S an approximate
    solve, e.g. with a float32 factor; the residual in float64)."""

    def refined(b: np.ndarray) -> np.ndarray:
        x = solve(b)
        return x + solve(b - A @ x)

    return refined


def _solve_mass(M: sp.csr_matrix, b: np.ndarray) -> np.ndarray:
    """M^-1 b for a mass matrix (SPD, condition number O(10) after diagonal scaling) by
    Jacobi-preconditioned conjugate gradients to round-off, instead of a factorisation.
    numpy's BLAS stays on one thread: right after numba's parallel products its threads
    stalled each dot product for milliseconds (CG took 1.3 s instead of 0.1 s on the demo)."""
    inv_diag = 1.0 / M.diagonal()
    pre = spla.LinearOperator(M.shape, matvec=lambda r: inv_diag * r, dtype=np.float64)
    op = spla.LinearOperator(M.shape, matvec=ParallelCSR(M).__matmul__, dtype=np.float64)
    with threadpool_limits(limits=1, user_api="blas"):
        x, info = spla.cg(op, b, rtol=1e-13, atol=0.0, maxiter=500, M=pre)
    return x if info == 0 else factorize(M)(b)
