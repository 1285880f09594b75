"""Per-joint interval polynomials for keyframes (seed 001 section 2.5).

An interval of length h (s) is described, for every joint, by cubic coefficients
``c`` (n, 4) in local time s in [0, h]: theta(s) = c0 + c1 s + c2 s^2 + c3 s^3 (rad).
"""

from __future__ import annotations

import numpy as np


def quadratic(theta1: np.ndarray, vel1: np.ndarray, theta2: np.ndarray, h: float) -> np.ndarray:
    """Quadratic through (theta1, theta1') at s = 0 and theta2 at s = h; returns (n, 4)."""
    c2 = (theta2 - theta1 - vel1 * h) / h**2
    return np.stack([theta1, vel1, c2, np.zeros_like(c2)], axis=-1)


def hermite(
    theta1: np.ndarray, vel1: np.ndarray, theta2: np.ndarray, vel2: np.ndarray, h: float
) -> np.ndarray:
    """Cubic Hermite through (theta1, theta1') at s = 0 and (theta2, theta2') at s = h."""
    d = theta2 - theta1
    c2 = (3.0 * d - (2.0 * vel1 + vel2) * h) / h**2
    c3 = (-2.0 * d + (vel1 + vel2) * h) / h**3
    return np.stack([theta1, vel1, c2, c3], axis=-1)


def evaluate(c: np.ndarray, s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angle, velocity and acceleration of polynomials c (n, 4) at local time(s) s.

    s scalar -> three (n,) arrays; s (T,) -> three (T, n) arrays (rad, rad/s, rad/s^2).
    """
    s = np.asarray(s, dtype=float)[..., None]
    c0, c1, c2, c3 = c[:, 0], c[:, 1], c[:, 2], c[:, 3]
    theta = c0 + s * (c1 + s * (c2 + s * c3))
    vel = c1 + s * (2.0 * c2 + 3.0 * s * c3)
    acc = 2.0 * c2 + 6.0 * s * c3
    return theta, vel, acc


def catmull_rom_velocities(times: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Default key velocities (K, n) rad/s: central differences, zero at the end keys."""
    v = np.zeros_like(angles)
    if len(times) > 2:
        v[1:-1] = (angles[2:] - angles[:-2]) / (times[2:] - times[:-2])[:, None]
    return v
