"""Prescribed joint motion of the seed (SPEC section 4, seed 000 eqs 25-27)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def seed_trajectory(
    t: ArrayLike, start: ArrayLike, delta: ArrayLike, duration: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Joint angles, velocities and accelerations of the seed's rest-to-rest motion.

    With s = t / duration in [0, 1]:
    theta(s) = (9 d / 16)(-cos(pi s) + cos(3 pi s) / 9) + theta(0) + d / 2, so theta goes from
    ``start`` to ``start + delta`` with zero velocity and acceleration at both ends.

    t: (T,) s; start, delta: (n,) rad; returns q (T, n) rad, qd (T, n) rad/s, qdd (T, n) rad/s^2.
    """
    if duration <= 0:
        raise ValueError(f"seed_trajectory: duration must be > 0 s, got {duration}")
    s = np.asarray(t, dtype=float)[:, None] / duration
    start = np.asarray(start, dtype=float)[None, :]
    delta = np.asarray(delta, dtype=float)[None, :]
    ps, p3s = np.pi * s, 3.0 * np.pi * s
    q = (9.0 * delta / 16.0) * (-np.cos(ps) + np.cos(p3s) / 9.0) + start + delta / 2.0
    qd = (9.0 * np.pi * delta / 16.0) * (np.sin(ps) - np.sin(p3s) / 3.0) / duration
    qdd = (9.0 * np.pi**2 * delta / 16.0) * (np.cos(ps) - np.cos(p3s)) / duration**2
    return q, qd, qdd
