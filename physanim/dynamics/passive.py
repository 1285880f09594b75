"""Passive motion with joint limits and friction factors (SPEC section 2.4, seed 001 2.4).

One step of length dt (s): T = 0 on the simulated joints; solve H qdd = T - B; velocity
qd_t = qd + qdd dt (eq 5); multiply each unclamped simulated component by its friction
factor; q_t = q + qd_m dt (eq 6); components that leave [min, max] are set to the nearer
limit, their accelerations recomputed by eq 7 and held fixed while eq 2 is re-solved for
the others; repeat from the velocity update until every component is within its limits.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from physanim.dynamics.figure import Figure
from physanim.dynamics.rigid import (
    GRAVITY,
    Method,
    Vec3,
    bias_forces,
    mass_matrix,
    solve_with_known,
)


@dataclass(frozen=True)
class StepResult:
    """State after one passive step: q (n,) rad, qd (n,) rad/s, the accelerations used
    qdd (n,) rad/s^2 and ``clamped`` (n,) bool, the components held at a limit."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    clamped: np.ndarray


def passive_step(
    fig: Figure,
    q: np.ndarray,
    qd: np.ndarray,
    dt: float,
    *,
    free: np.ndarray | None = None,
    prescribed_qdd: np.ndarray | None = None,
    friction: np.ndarray | None = None,
    tau: np.ndarray | None = None,
    method: Method = "crba",
    gravity: np.ndarray | Vec3 = GRAVITY,
    base_acc: np.ndarray | None = None,
    ext_forces: Mapping[str, np.ndarray] | None = None,
) -> StepResult:
    """Advance the simulated joints by one step of ``dt`` s (SPEC section 2.4).

    q, qd: (n,) rad, rad/s.  ``free`` (n,) bool selects the simulated joints (default
    all); the others move with ``prescribed_qdd`` (n,) rad/s^2 (their entries only) and
    are integrated without friction or limits (a caller that knows them exactly may
    overwrite them).  ``friction`` (n,) factors in [0, 1] per step (default the
    figure's); ``tau`` (n,) N m on the simulated joints (default 0, passive).
    """
    n = fig.n_dof
    if dt <= 0:
        raise ValueError(f"dt must be > 0 s, got {dt}")
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    free = np.ones(n, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    fric = fig.friction if friction is None else np.asarray(friction, dtype=float)
    known = ~free
    known_qdd = np.zeros(n) if prescribed_qdd is None else np.array(prescribed_qdd, dtype=float)
    rhs = (np.zeros(n) if tau is None else np.asarray(tau, float)) - bias_forces(
        fig, q, qd, gravity=gravity, base_acc=base_acc, ext_forces=ext_forces
    )
    h = mass_matrix(fig, q, method=method)
    clamped = np.zeros(n, dtype=bool)
    qdd = solve_with_known(h, rhs, known, known_qdd)
    for _ in range(n + 1):  # each pass clamps at least one more component
        qd_m = (qd + qdd * dt) * np.where(free & ~clamped, fric, 1.0)  # eq 5 and step 7
        q_t = q + qd_m * dt  # eq 6
        out = free & ~clamped & ((q_t < fig.lower) | (q_t > fig.upper))
        if not out.any():
            break
        q_t[out] = np.clip(q_t[out], fig.lower[out], fig.upper[out])
        clamped |= out
        known = known | out
        known_qdd[out] = ((q_t[out] - q[out]) / dt - qd[out]) / dt  # eq 7
        qdd = solve_with_known(h, rhs, known, known_qdd)
    return StepResult(q_t, qd_m, qdd, clamped)


def simulate_passive(
    fig: Figure,
    q0: np.ndarray,
    qd0: np.ndarray,
    dt: float,
    steps: int,
    *,
    progress: Callable[[int, int], None] | None = None,
    **step_kwargs: object,
) -> tuple[np.ndarray, np.ndarray]:
    """Passive trajectory from (q0, qd0): returns q, qd, each (steps + 1, n).

    ``step_kwargs`` are passed to :func:`passive_step` (free, friction, gravity, ...).
    """
    q = np.empty((steps + 1, fig.n_dof))
    qd = np.empty_like(q)
    q[0], qd[0] = q0, qd0
    for k in range(steps):
        r = passive_step(fig, q[k], qd[k], dt, **step_kwargs)
        q[k + 1], qd[k + 1] = r.q, r.qd
        if progress is not None:
            progress(k + 1, steps)
    return q, qd
