"""Inverse dynamics (SPEC eq 1), inertia matrix (eqs 3-4 or CRBA) and forward dynamics (eq 2,
or the articulated-body algorithm).

The base is fixed in orientation (base frame = world axes) and may accelerate linearly.
Joint torques follow ``H(q) qdd + B(q, qd) = tau``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

import numpy as np

from physanim.dynamics.figure import Figure
from physanim.dynamics.kernels import aba, crba, rnea_batch
from physanim.dynamics.kinematics import _as_batch, forward_kinematics, link_coms

Vec3 = tuple[float, float, float]
GRAVITY: Vec3 = (0.0, -9.81, 0.0)
Method = Literal["crba", "rnea"]
ForwardMethod = Literal["aba", "crba", "rnea"]
_MINUS_G = -np.asarray(GRAVITY)
_NONE = np.zeros(0)  # ``aba``: no joint torques
_NO_LOADS = np.zeros((0, 6))  # ``aba``: no external loads


def _base_term(gravity: np.ndarray | Vec3, base_acc: np.ndarray | None, nb: int) -> np.ndarray:
    """a = base acceleration minus gravity, (B, 3) m/s^2."""
    g = np.asarray(gravity, dtype=float)
    a = -g if base_acc is None else np.asarray(base_acc, dtype=float) - g
    out = np.empty((nb, 3))
    try:
        out[:] = a
    except ValueError:
        raise ValueError(f"base_acc/gravity must be (3,) or ({nb}, 3), got {a.shape}") from None
    return out


def _ext_array(fig: Figure, ext_forces: Mapping[str, np.ndarray] | None, nb: int) -> np.ndarray:
    """(B, n, 6) external [force N, moment N m] on each link's tip, world frame."""
    out = np.zeros((nb, fig.n_dof, 6))
    for name, load in (ext_forces or {}).items():
        arr = np.asarray(load, dtype=float)
        if arr.shape not in ((6,), (nb, 6)):
            raise ValueError(
                f"ext_forces[{name!r}] must be (6,) [fx, fy, fz, mx, my, mz] or ({nb}, 6), "
                f"got {arr.shape}"
            )
        out[:, fig.index(name)] = arr
    return out


def inverse_dynamics(
    fig: Figure,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    *,
    gravity: np.ndarray | Vec3 = GRAVITY,
    base_acc: np.ndarray | None = None,
    ext_forces: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """Joint torques tau (n,) or (T, n), N m, by recursive Newton-Euler (SPEC eq 1).

    q, qd, qdd: (n,) or (T, n) in rad, rad/s, rad/s^2.  ``gravity`` (3,) m/s^2;
    ``base_acc`` (3,) or (T, 3) m/s^2 linear acceleration of the base; ``ext_forces``
    maps a link name to the load (6,) or (T, 6) [fx, fy, fz (N), mx, my, mz (N m)]
    that the environment exerts on that link at its distal end, world axes.
    """
    q2, single = _as_batch(fig, q, "q")
    qd2, _ = _as_batch(fig, np.broadcast_to(qd, q2.shape), "qd")
    qdd2, _ = _as_batch(fig, np.broadcast_to(qdd, q2.shape), "qdd")
    nb = len(q2)
    tau = rnea_batch(
        fig.parent,
        fig.axis,
        fig.offset,
        fig.mass,
        fig.com,
        fig.inertia,
        fig.tips,
        q2,
        qd2,
        qdd2,
        _base_term(gravity, base_acc, nb),
        _ext_array(fig, ext_forces, nb),
    )
    return tau[0] if single else tau


def mass_matrix(fig: Figure, q: np.ndarray, *, method: Method = "crba") -> np.ndarray:
    """Joint-space inertia H (n, n), kg m^2, at q (n,) rad.

    ``method="rnea"`` is the seed's eq 4 (column i = D_inv(q, 0, e_i, 0, 0, 0), all
    columns in one batched call); ``"crba"`` the composite-rigid-body algorithm.
    """
    q2, _ = _as_batch(fig, q)
    n = fig.n_dof
    if method == "crba":
        return crba(fig.parent, fig.packed, q2[0])
    if method == "rnea":
        h = rnea_batch(
            fig.parent,
            fig.axis,
            fig.offset,
            fig.mass,
            fig.com,
            fig.inertia,
            fig.tips,
            np.ascontiguousarray(np.broadcast_to(q2[0], (n, n))),
            np.zeros((n, n)),
            np.eye(n),
            np.zeros((n, 3)),
            np.zeros((n, n, 6)),
        )
        return h.T  # row b of the batch is column b of H
    raise ValueError(f"method must be 'crba' or 'rnea', got {method!r}")


def bias_forces(
    fig: Figure,
    q: np.ndarray,
    qd: np.ndarray,
    *,
    gravity: np.ndarray | Vec3 = GRAVITY,
    base_acc: np.ndarray | None = None,
    ext_forces: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """Bias vector B = D_inv(q, qd, 0, a, K_f, K_n) (SPEC eq 3), N m; shapes as q."""
    return inverse_dynamics(
        fig,
        q,
        qd,
        np.zeros_like(np.asarray(q, float)),
        gravity=gravity,
        base_acc=base_acc,
        ext_forces=ext_forces,
    )


def solve_with_known(
    h: np.ndarray, rhs: np.ndarray, known: np.ndarray, known_qdd: np.ndarray
) -> np.ndarray:
    """Solve H qdd = rhs (n,) where the components ``known`` (n,) bool are fixed.

    The unknown rows are solved with the known accelerations moved to the right-hand
    side (SPEC section 2, step 11); returns the full qdd (n,) rad/s^2.
    """
    if not known.any():
        return np.linalg.solve(h, rhs)
    qdd = np.where(known, known_qdd, 0.0)
    free = ~known
    if free.any():
        r = rhs[free] - h[np.ix_(free, known)] @ qdd[known]
        qdd[free] = np.linalg.solve(h[np.ix_(free, free)], r)
    return qdd


def _joint_vector(fig: Figure, x: np.ndarray | None, name: str) -> np.ndarray:
    """``x`` as a float (n,) array (zeros if None); ValueError naming ``name`` otherwise."""
    if x is None:
        return np.zeros(fig.n_dof)
    a = np.asarray(x, dtype=float)
    if a.shape != (fig.n_dof,):
        raise ValueError(
            f"{name} must have shape ({fig.n_dof},) for figure {fig.name!r}, got {a.shape}"
        )
    return a


def forward_dynamics(
    fig: Figure,
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray | None = None,
    *,
    method: ForwardMethod = "aba",
    gravity: np.ndarray | Vec3 = GRAVITY,
    base_acc: np.ndarray | None = None,
    ext_forces: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """Joint accelerations qdd (n,) rad/s^2 of H qdd = tau - B (SPEC eq 2).

    q, qd, tau: (n,) rad, rad/s, N m (tau defaults to zero: passive motion).  ``method``
    ``"aba"`` (default) runs Featherstone's O(n) articulated-body algorithm; ``"crba"`` and
    ``"rnea"`` build H (see :func:`mass_matrix`) and the bias B by Newton-Euler and solve.
    The other arguments as in :func:`inverse_dynamics`.  All three agree to rounding.
    """
    if method == "aba":
        if gravity is GRAVITY and base_acc is None:
            a0 = _MINUS_G
        else:
            a0 = _base_term(gravity, base_acc, 1)[0]
        return aba(
            fig.parent,
            fig.packed,
            _joint_vector(fig, q, "q"),
            _joint_vector(fig, qd, "qd"),
            _NONE if tau is None else _joint_vector(fig, tau, "tau"),
            a0,
            _NO_LOADS if ext_forces is None else _ext_array(fig, ext_forces, 1)[0],
        )
    if method not in ("crba", "rnea"):
        raise ValueError(f"method must be 'aba', 'crba' or 'rnea', got {method!r}")
    n = fig.n_dof
    t = _joint_vector(fig, tau, "tau")
    b = bias_forces(fig, q, qd, gravity=gravity, base_acc=base_acc, ext_forces=ext_forces)
    h = mass_matrix(fig, q, method=method)
    return solve_with_known(h, t - b, np.zeros(n, dtype=bool), np.zeros(n))


def mechanical_energy(
    fig: Figure, q: np.ndarray, qd: np.ndarray, *, gravity: np.ndarray | Vec3 = GRAVITY
) -> float:
    """Kinetic (1/2 qd^T H qd) plus gravitational potential energy, J, of a fixed-base pose."""
    qd = np.asarray(qd, dtype=float)
    kinetic = 0.5 * qd @ mass_matrix(fig, q) @ qd
    coms = link_coms(fig, forward_kinematics(fig, q))
    return float(kinetic - fig.mass @ coms @ np.asarray(gravity, dtype=float))
