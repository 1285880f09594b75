"""Muscle force sharing: tendon forces F (T, m) N whose joint torques equal tau (T, n) N m.

Torque of the muscles at joint j: sum_k R[t, k, j] F[t, k] (seed eqs 10-11), with R the moment
arms (T, m, n) m.  At a given fibre state each muscle's force is an increasing function F(a)
of its activation a in [0, 1] (``force_of``); static optimisation works on a itself.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import lsq_linear

NEWTON_STEPS = 100
FEASIBILITY_TOL = 1e-9  # N m, torque residual accepted by the QP
SQP_STEPS = 50  # linearisations of F(a) in static optimisation
ACTIVATION_TOL = 1e-12  # change in a that ends them


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


def _dual_newton(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Maximise the dual of min 1/2 |x|^2 s.t. A x = b, lo <= x <= hi; returns x(lam) (T, m).

    x(lam) = clip(A^T lam, lo, hi) minimises the Lagrangian; the concave dual is maximised by
    semismooth Newton steps with backtracking, which end exactly once the active set is right.
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
    return primal(lam)


def box_qp(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Batched min 1/2 |x|^2 s.t. A x = b, lo <= x <= hi (dual Newton, :func:`_dual_newton`).

    a (T, n, m), b (T, n), lo/hi (T, m).  Rows whose constraints cannot be met inside the box
    get the closest reachable right-hand side b* (bounded least squares; b* is unique, the box's
    image being convex) and then the smallest x with A x = b*: no load-free co-contraction.
    Returns x (T, m) and the residual A x - b (T, n).
    """
    x = _dual_newton(a, b, lo, hi)
    resid = np.einsum("tnm,tm->tn", a, x) - b
    bad = np.flatnonzero(np.any(np.abs(resid) > FEASIBILITY_TOL, axis=1))
    if bad.size:
        reach = np.empty((bad.size, b.shape[1]))
        for k, i in enumerate(bad):  # infeasible rows only: the closest reachable torques
            upper = np.where(hi[i] > lo[i], hi[i], np.nextafter(lo[i], np.inf))
            x[i] = lsq_linear(a[i], b[i], bounds=(lo[i], upper), method="bvls").x
            reach[k] = a[i] @ x[i]
        smallest = _dual_newton(a[bad], reach, lo[bad], hi[bad])
        met = np.all(
            np.abs(np.einsum("tnm,tm->tn", a[bad], smallest) - reach) <= FEASIBILITY_TOL, 1
        )
        x[bad[met]] = smallest[met]
        resid = np.einsum("tnm,tm->tn", a, x) - b
    return x, resid


def static_optimisation(
    moment_arm: NDArray[np.float64],
    torque: NDArray[np.float64],
    force_of: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    lower: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Activations minimising sum_k a_k^2 with lower <= a <= 1 and R^T F(a) = tau, exactly.

    moment_arm R (T, m, n) m; torque tau (T, n) N m; ``force_of(a)`` the tendon forces (T, m)
    N at activations a (T, m) (fixed fibre state, increasing in a); ``lower`` (T, m) the
    co-contraction floor.  F(a) is linearised at the current a and the box QP solved again
    until a stops changing (sequential quadratic programming with the objective's Hessian;
    its fixed point satisfies the KKT conditions of the nonlinear problem).  Torques out of
    reach are replaced by the closest reachable ones: returns a (T, m) and the torques the
    muscles produce (T, n), equal to ``torque`` wherever it is reachable.
    """
    ones = np.ones_like(lower)
    f_lo, f_hi = force_of(lower), force_of(ones)
    gain = np.maximum(f_hi - f_lo, 0.0)
    # reachable torques: forces anywhere in [F(lower), F(1)] (F is monotone in a)
    a_mat = np.einsum("tmn,tm->tnm", moment_arm, gain)
    x, resid = box_qp(
        a_mat, torque - np.einsum("tmn,tm->tn", moment_arm, f_lo), np.zeros_like(lower), ones
    )
    target = np.where(np.abs(resid) > FEASIBILITY_TOL, torque + resid, torque)
    a = lower + x * (1.0 - lower)  # start from the linear interpolation
    step = 1e-7
    for _ in range(SQP_STEPS):
        f = force_of(a)
        up, down = np.minimum(a + step, 1.0), np.maximum(a - step, 0.0)
        slope = np.maximum((force_of(up) - force_of(down)) / (up - down), 0.0)
        a_mat = np.einsum("tmn,tm->tnm", moment_arm, slope)
        rhs = target - np.einsum("tmn,tm->tn", moment_arm, f - slope * a)
        new, _ = box_qp(a_mat, rhs, lower, ones)
        change = np.abs(new - a).max()
        a = new
        if change <= ACTIVATION_TOL:
            break
    return a, np.einsum("tmn,tm->tn", moment_arm, force_of(a))
