"""Muscle force sharing: tendon forces F (T, m) N whose joint torques equal tau (T, n) N m.

Torque of the muscles at joint j: sum_k R[t, k, j] F[t, k] (seed eqs 10-11), with R the moment
arms (T, m, n) m.  Each muscle's force lies between its floor P (the force at a = 0, passive,
or the co-contraction minimum) and P + G (G: the extra force at a = 1), both (T, m) N, at the
current fibre state.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import lsq_linear

NEWTON_STEPS = 100
FEASIBILITY_TOL = 1e-9  # N m, torque residual accepted by the QP


def seed_rule(
    moment_arm: NDArray[np.float64],
    torque: NDArray[np.float64],
    floor: NDArray[np.float64],
    joint_of_muscle: NDArray[np.int_],
) -> NDArray[np.float64]:
    """The seed's rule: every muscle carries its floor; the muscle whose moment has the sign of
    the remaining torque at its joint carries the rest (seed section 4.3).

    moment_arm (T, m, n) m; torque (T, n) N m; floor (T, m) N; joint_of_muscle (m,) the single
    joint each muscle crosses.  Each joint needs exactly one flexor (R > 0) and one extensor
    (R < 0).  Returns F (T, m) N, exact up to rounding; forces may exceed what a muscle can give
    (that shows up as shortfall in the activation solve).
    """
    t = np.arange(torque.shape[0])
    r_own = moment_arm[:, np.arange(len(joint_of_muscle)), joint_of_muscle]  # (T, m)
    force = floor.copy()
    for j in range(torque.shape[1]):
        crossing = np.flatnonzero(joint_of_muscle == j)
        if crossing.size != 2:
            raise ValueError(
                f"seed_rule: joint {j} is crossed by {crossing.size} muscles; the seed's rule "
                "needs exactly one flexor and one extensor per joint (use static_optimisation)"
            )
        remaining = torque[:, j] - np.einsum(
            "tk,tk->t", moment_arm[:, crossing, j], floor[:, crossing]
        )
        r = r_own[:, crossing]  # (T, 2)
        agonist = crossing[np.argmax(np.sign(remaining)[:, None] * r, axis=1)]
        r_ag = r_own[t, agonist]
        if np.any(np.sign(r_ag) * np.sign(remaining) < 0):
            raise ValueError(f"seed_rule: the two muscles at joint {j} pull the same way")
        force[t, agonist] += remaining / r_ag
    return force


def _clip(x: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]):
    return np.minimum(np.maximum(x, lo), hi)


def box_qp(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Batched min 1/2 |x|^2 s.t. A x = b, lo <= x <= hi, by Newton's method on the dual.

    a (T, n, m), b (T, n), lo/hi (T, m).  x(lam) = clip(A^T lam, lo, hi) minimises the
    Lagrangian; the concave dual g(lam) is maximised by semismooth Newton steps with
    backtracking, which end exactly once the active set is right.  Rows whose constraints
    cannot be met inside the box get the least-squares point of the box instead.  Returns x
    (T, m) and the residual A x - b (T, n).
    """
    nt, n, _ = a.shape
    lam = np.zeros((nt, n))

    def primal(lam_: NDArray[np.float64]) -> NDArray[np.float64]:
        return _clip(np.einsum("tnm,tn->tm", a, lam_), lo, hi)

    def dual(lam_: NDArray[np.float64]) -> NDArray[np.float64]:
        x_ = primal(lam_)
        r_ = np.einsum("tnm,tm->tn", a, x_) - b
        return 0.5 * np.sum(x_**2, axis=1) - np.sum(lam_ * r_, axis=1)

    eye = 1e-9 * np.einsum("tnm,tnm->t", a, a)[:, None, None] * np.eye(n)  # keeps steps finite
    for _ in range(NEWTON_STEPS):
        x = primal(lam)
        grad = b - np.einsum("tnm,tm->tn", a, x)
        if np.all(np.abs(grad) <= FEASIBILITY_TOL):
            break
        z = np.einsum("tnm,tn->tm", a, lam)
        free = (z >= lo) & (z < hi)  # at a kink, take the free branch
        hess = np.einsum("tnm,tm,tkm->tnk", a, free.astype(float), a) + eye
        step = np.linalg.solve(hess, grad[..., None])[..., 0]
        g0, scale = dual(lam), np.ones(nt)
        for _ in range(40):  # backtrack until the dual does not decrease
            worse = dual(lam + scale[:, None] * step) < g0 - 1e-15 * np.abs(g0)
            if not worse.any():
                break
            scale = np.where(worse, 0.5 * scale, scale)
        lam = lam + scale[:, None] * step
    x = primal(lam)
    resid = np.einsum("tnm,tm->tn", a, x) - b
    bad = np.flatnonzero(np.any(np.abs(resid) > FEASIBILITY_TOL, axis=1))
    for i in bad:  # infeasible rows only: the closest reachable torques
        upper = np.where(hi[i] > lo[i], hi[i], np.nextafter(lo[i], np.inf))
        x[i] = lsq_linear(a[i], b[i], bounds=(lo[i], upper)).x
    if bad.size:
        resid = np.einsum("tnm,tm->tn", a, x) - b
    return x, resid


def static_optimisation(
    moment_arm: NDArray[np.float64],
    torque: NDArray[np.float64],
    floor: NDArray[np.float64],
    gain: NDArray[np.float64],
    minimum: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Forces minimising the sum of squared activations, a_k = (F_k - P_k) / G_k in [0, 1].

    A QP in activation space with the force model linearised at the current fibre state:
    F = P + G a.  moment_arm (T, m, n) m; torque (T, n) N m; floor P and gain G (T, m) N;
    ``minimum`` (T, m) N optional lower bound on F (co-contraction).  Returns F (T, m) N;
    where the torques are out of reach, the closest reachable ones (the activation solve then
    reports the gap).
    """
    g = np.maximum(gain, 1e-12)
    lo = np.zeros_like(floor)
    if minimum is not None:
        lo = np.clip((minimum - floor) / g, 0.0, 1.0)
    a_mat = np.einsum("tmn,tm->tnm", moment_arm, g)
    b = torque - np.einsum("tmn,tm->tn", moment_arm, floor)
    x, _ = box_qp(a_mat, b, lo, np.ones_like(lo))
    return floor + g * x
