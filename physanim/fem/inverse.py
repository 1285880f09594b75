"""The inverse step: the actuation with which the FEM reproduces observed skin motion.

At a fixed material (the *basis material*) and under Dirichlet conditions (prescribed DOFs c
at d_c(t), e.g. the skull held and the mandible turned), the static FEM's free displacements
at capture frame t are linear in the actuation coefficients a_t (P, 5) Pa of a
:class:`~physanim.fem.actuation.StressBasis`:

    d_u(t) = K_uu^-1 (-K_uc d_c(t)) + K_uu^-1 F_u a_t = p(t) + R a_t,

F the basis' active forces per Pa (``StressBasis.force_matrix``). With S observed nodes (the
skin) at targets y(t) (T, S, 3) m and weights w(t) (T, S) (skin area x capture confidence),
the coefficients of all frames minimise

    sum_t [ sum_i w_ti |(p + R a)_ti - y_ti|^2 / sum_i w_ti
            + lambda sum_p c_p^2 v_p |a_tp|^2 + mu sum_p v_p |a_tp - a_(t-1)p|^2 ],

v_p each patch's share of the tissue volume, c_p its stress cost factor (1 by default; a
region held to stiffer stresses, > 1): the first term is the weighted mean square
misfit (m^2), the others the mean square active stress over the tissue and its mean square
change per frame (Pa^2), with lambda = ``stress_cost``^2 and mu = ``rate_cost``^2 (m/Pa: an
RMS stress of 1 Pa costs as much as an RMS misfit of ``stress_cost`` m). Small norm keeps
patches that move no observed node at zero; the smooth patches make the stress smooth in
space, the difference penalty smooth in time.

Cost: one factorisation of K_uu, 5 P + r solves (multi right-hand side; r the rank of the
prescribed motion over the frames, 2 for a mandible turning about one axis), then the normal
equations, coupled over frames by the difference penalty, by conjugate gradients
preconditioned with their exact solution for the frame-mean weights: with
v^-1/2 (H + lambda U) v^-1/2 = Q Lambda Q^T (H = R^T W R, U = diag(c^2 v)) and the
first-difference Laplacian L = P Gamma P^T the system is diagonal, (Lambda_i + mu Gamma_j).
When the weights do not change over frames that is the solution to the preconditioner's
single precision (one or two iterations to 1e-6).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from physanim.fem.actuation import DEVIATORIC, StressBasis
from physanim.fem.boundary import BoundaryConditions
from physanim.fem.geometry import node_dofs
from physanim.fem.linsolve import factorize_many
from physanim.fem.model import FemModel
from physanim.fem.statics import free_dofs

#: right-hand sides per multi-RHS solve (bounds the memory of the solves, n_u x this)
SOLVE_BLOCK = 128
#: reweightings of the robust (Huber) fit
ROBUST_ROUNDS = 2


@dataclass(frozen=True)
class ActuationFit:
    """The inverse step's answer for T frames and S observed nodes: ``coefficients``
    (T, P, 5) Pa; the static FEM's displacements of the observed nodes with them,
    ``fitted`` (T, S, 3) m, and without actuation (the conditions alone), ``passive``
    (T, S, 3) m; conjugate-gradient ``iterations`` (all rounds); ``seconds`` per step."""

    coefficients: NDArray
    fitted: NDArray
    passive: NDArray
    iterations: int
    seconds: dict[str, float] = field(default_factory=dict)


def _observed_positions(observed: NDArray, free: NDArray) -> NDArray:
    """Positions (3S,) of the observed nodes' DOFs among the ``free`` DOFs; ValueError when
    one is prescribed."""
    dofs = node_dofs(np.asarray(observed, dtype=np.int64))
    at = np.searchsorted(free, dofs)
    if np.any(at >= len(free)) or not np.array_equal(free[np.minimum(at, len(free) - 1)], dofs):
        raise ValueError("observed nodes must be free (not prescribed)")
    return at


def response(
    model: FemModel,
    basis: StressBasis,
    conditions: BoundaryConditions,
    observed: NDArray,
    solver: str = "auto",
) -> tuple[NDArray, NDArray, dict[str, float]]:
    """The static responses of the ``observed`` (S,) nodes: R (3S, 5P) m per Pa of each
    coefficient and the passive displacements p (T, 3S) m under ``conditions`` alone; with
    the seconds spent factorising K_uu and solving."""
    t0 = time.perf_counter()
    pres = conditions.prescribed_dofs
    free = free_dofs(model.n_dofs, pres)
    at = _observed_positions(observed, free)
    rows = sp.csr_matrix(model.K)[free]
    solve = factorize_many(rows[:, free], solver)
    t_fac = time.perf_counter() - t0
    t0 = time.perf_counter()
    d_c = conditions.prescribed(conditions.frame_dt * np.arange(conditions.n_frames))[0]
    # the prescribed motion of all frames spans few shapes (a mandible turning about one
    # axis: two): d_c = C V, so the passive responses need a solve per shape, not per frame
    u, sv, vt = np.linalg.svd(d_c, full_matrices=False)
    rank = int(np.count_nonzero(sv > sv[0] * 1e-12)) if sv.size and sv[0] > 0 else 0
    forces = basis.force_matrix(model)[free]
    shapes = -(rows[:, pres] @ vt[:rank].T)
    rhs = sp.hstack([forces, sp.csc_matrix(shapes)], format="csc")
    out = np.empty((len(at), rhs.shape[1]))
    for j in range(0, rhs.shape[1], SOLVE_BLOCK):
        out[:, j : j + SOLVE_BLOCK] = solve(rhs[:, j : j + SOLVE_BLOCK].toarray())[at]
    passive = (u[:, :rank] * sv[:rank]) @ out[:, basis.size :].T
    seconds = {"factorization": t_fac, "solves": time.perf_counter() - t0}
    return out[:, : basis.size], passive, seconds


def _difference_laplacian(n: int, anchored: bool = False) -> NDArray:
    """L (n, n) with a^T L a = sum_t |a_t - a_(t-1)|^2, the first differences of n frames,
    or with ``anchored`` of n frames after one held at zero (whose step counts too)."""
    D = np.diff(np.eye(n + anchored), axis=0)[:, anchored:]
    return D.T @ D


def _normalised(weights: NDArray) -> NDArray:
    """Weights (T, S) / their sum per frame, repeated over x, y, z: (T, 3S)."""
    total = weights.sum(axis=1, keepdims=True)
    share = np.divide(weights, total, out=np.zeros_like(weights), where=total > 0)
    return np.repeat(share, 3, axis=1)


class LeastSquares:
    """The normal equations of the module docstring's objective for responses R (3S, n) m/Pa
    over T frames, ``volume_share`` (n,) v of each coefficient's patch, ``stress_cost`` and
    ``rate_cost`` m/Pa (``anchored``: the T frames follow one whose coefficients are held
    at zero); ``stress_factor`` (n,) each coefficient's stress penalty times this (default
    1); preconditioned by their exact solution for the per-frame weights ``mean_weights``
    (S,) used in every frame (diagonal in the eigenvectors Q of v^-1/2 (H + lambda U)
    v^-1/2, U = diag(v ``stress_factor``), and P of the first-difference Laplacian)."""

    def __init__(
        self,
        R: NDArray,
        volume_share: NDArray,
        stress_cost: float,
        rate_cost: float,
        mean_weights: NDArray,
        n_frames: int,
        anchored: bool = False,
        stress_factor: NDArray | None = None,
    ) -> None:
        self.R, self.v = R, np.asarray(volume_share, dtype=np.float64)
        self.u = self.v if stress_factor is None else self.v * np.asarray(stress_factor)
        self.lam, self.mu = stress_cost**2, rate_cost**2
        self.lap = _difference_laplacian(n_frames, anchored)
        self.s = 1.0 / np.sqrt(self.v)
        hbar = (R * _normalised(mean_weights[None])[0][:, None]).T @ R
        hbar[np.diag_indices_from(hbar)] += self.lam * self.u
        # the preconditioner in single precision: it need only be near the inverse, and its
        # eigendecomposition (LAPACK's divide and conquer: numpy's eigh gains nothing in
        # single) and products took half the least squares' time in double
        scaled = (self.s[:, None] * hbar * self.s[None, :]).astype(np.float32)
        eig_h, self.Q = scipy.linalg.eigh(scaled, driver="evd", check_finite=False)
        eig_l, P = np.linalg.eigh(self.lap)
        self.P = P.astype(np.float32)
        # its eigenvalues are at least lambda min(stress_factor): a floor against round-off
        floor = self.lam * float((self.u / self.v).min())
        denom = np.maximum(eig_h, floor)[:, None] + self.mu * eig_l[None, :]
        self.inv_denom = (1.0 / denom).astype(np.float32)

    def _precondition(self, r: NDArray) -> NDArray:
        s, Q, P = self.s[:, None], self.Q, self.P
        inner = (Q.T @ (s * r).astype(np.float32) @ P) * self.inv_denom
        return s * (Q @ inner @ P.T)

    def solve(
        self,
        residual_targets: NDArray,
        weights: NDArray,
        start: NDArray | None = None,
        rtol: float = 1e-6,
        max_iter: int = 500,
    ) -> tuple[NDArray, int]:
        """The minimiser a (T, n) for targets minus passive motion ``residual_targets``
        (T, 3S) m and ``weights`` (T, S) >= 0, by conjugate gradients from ``start`` (T, n)
        (default: the preconditioned guess); and the iterations taken."""
        R, u, v, w = self.R, self.u[:, None], self.v[:, None], _normalised(weights)

        def apply(a: NDArray) -> NDArray:  # a (n, T) -> the normal equations' matrix times a
            return R.T @ (w.T * (R @ a)) + self.lam * u * a + self.mu * v * (a @ self.lap)

        b = R.T @ (w * residual_targets).T  # (n, T)
        a = self._precondition(b) if start is None else start.T.copy()
        r = b - apply(a)
        z = self._precondition(r)
        p, rz = z.copy(), float((r * z).sum())
        norm_b, it = float(np.linalg.norm(b)), 0
        while np.linalg.norm(r) > rtol * norm_b and it < max_iter:
            q = apply(p)
            alpha = rz / float((p * q).sum())
            a += alpha * p
            r -= alpha * q
            z = self._precondition(r)
            rz, rz_old = float((r * z).sum()), rz
            p = z + (rz / rz_old) * p
            it += 1
        return a.T, it


def fit_actuation(
    model: FemModel,
    basis: StressBasis,
    conditions: BoundaryConditions,
    observed: NDArray,
    targets: NDArray,
    weights: NDArray,
    stress_cost: float,
    rate_cost: float,
    solver: str = "auto",
    robust: float = 0.0,
    patch_cost: NDArray | None = None,
) -> ActuationFit:
    """The actuation with which ``model`` (the basis material, static) under ``conditions``
    (driven and fixed nodes; no springs) moves the ``observed`` (S,) free nodes to
    ``targets`` (T, S, 3) m displacements from frame 0, weighted by ``weights`` (T, S) >= 0;
    penalties ``stress_cost`` and ``rate_cost`` in m/Pa (module docstring). Frame 0 is the
    rest: its actuation is zero (so a run starts from rest, with no static solve).

    ``robust`` > 0 (m): Huber's loss instead of the square for each node's misfit e beyond
    it, by ``ROBUST_ROUNDS`` reweightings w -> w min(1, robust / e), each warm-started from
    the last: motion the conditions contradict (a node the prescribed bone drags where the
    capture holds it) no longer calls for stresses far beyond the rest of the face's.

    ``patch_cost`` (P,) > 0: each patch's stress cost times this (default 1; the rate cost
    stays), by counting its volume share ``patch_cost``^2 times in the stress penalty."""
    n_frames, n_obs = np.shape(weights)
    if conditions.springs is not None:
        raise ValueError("the inverse step takes Dirichlet conditions only, not springs")
    if np.shape(targets) != (n_frames, n_obs, 3) or n_frames != conditions.n_frames:
        raise ValueError(
            f"targets {np.shape(targets)} and weights {np.shape(weights)} must be (T, S, 3) "
            f"and (T, S) with T = {conditions.n_frames} frames"
        )
    if np.any(weights < 0) or not np.isfinite(weights).all():
        raise ValueError("weights must be finite and >= 0")
    R, passive, seconds = response(model, basis, conditions, observed, solver)
    t0 = time.perf_counter()
    vol = basis.patch_volumes(model.volumes)
    factor = np.ones(basis.n_patches) if patch_cost is None else np.asarray(patch_cost, float)
    if factor.shape != (basis.n_patches,) or not np.all(factor > 0):
        raise ValueError(f"patch_cost must be ({basis.n_patches},) and > 0")
    share = np.repeat(vol / vol.sum(), len(DEVIATORIC))
    # frame 0 is the rest the motion is measured from: no actuation there (a = 0), the other
    # frames' coefficients are the unknowns, anchored to it by the difference penalty
    rest = np.zeros((1, R.shape[1]))
    y = np.asarray(targets, dtype=np.float64).reshape(n_frames, -1)[1:] - passive[1:]
    weights = np.asarray(weights, dtype=np.float64)[1:]
    # dense products of a few hundred columns: one BLAS thread (two, on cores other
    # processes use, took 10 times as long on the demo)
    with threadpool_limits(limits=1, user_api="blas"):
        ls = LeastSquares(
            R, share, stress_cost, rate_cost, weights.mean(axis=0), n_frames - 1, True,
            np.repeat(factor**2, len(DEVIATORIC)),
        )  # fmt: skip
        a, iterations = ls.solve(y, weights)
        for _ in range(ROBUST_ROUNDS if robust > 0 else 0):
            misfit = np.linalg.norm((a @ R.T - y).reshape(n_frames - 1, n_obs, 3), axis=2)
            huber = weights * np.minimum(1.0, robust / np.maximum(misfit, 1e-300))
            a, more = ls.solve(y, huber, start=a)
            iterations += more
    a = np.vstack([rest, a])
    seconds["least_squares"] = time.perf_counter() - t0
    return ActuationFit(
        coefficients=a.reshape(n_frames, basis.n_patches, len(DEVIATORIC)),
        fitted=(passive + a @ R.T).reshape(n_frames, n_obs, 3),
        passive=passive.reshape(n_frames, n_obs, 3),
        iterations=iterations,
        seconds=seconds,
    )
