"""C1 cubic (Catmull-Rom) interpolation of frame-rate trajectories, with time derivatives."""

from __future__ import annotations

import numpy as np


def tangents(values: np.ndarray, frame_dt: float) -> np.ndarray:
    """Catmull-Rom tangents (T, K) of ``values`` (T >= 2, K) sampled every ``frame_dt`` s: central
    differences, one-sided at the ends, in units of ``values`` per s."""
    values = np.asarray(values, dtype=np.float64)
    h = float(frame_dt)
    tang = np.empty_like(values)
    tang[1:-1] = (values[2:] - values[:-2]) / (2 * h)
    tang[0] = (values[1] - values[0]) / h
    tang[-1] = (values[-1] - values[-2]) / h
    return tang


def catmull_rom(
    values: np.ndarray, frame_dt: float, times: np.ndarray, tang: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of a uniform Catmull-Rom spline at ``times``.

    values (T, K) sampled at t_k = k frame_dt (s); times (S,) in [0, (T-1) frame_dt].
    Tangents are central differences, one-sided at the ends. Returns three (S, K) arrays in
    the units of ``values`` per s^0, s^1 and s^2. ``tang``: the :func:`tangents` of
    ``values``, when already computed.
    """
    s, p0, p1, m0, m1, h = _segments(values, frame_dt, times, tang)
    s2, s3 = s * s, s * s * s
    pos = (
        (2 * s3 - 3 * s2 + 1) * p0
        + (s3 - 2 * s2 + s) * m0
        + (3 * s2 - 2 * s3) * p1
        + (s3 - s2) * m1
    )
    vel = (
        (6 * s2 - 6 * s) * p0
        + (3 * s2 - 4 * s + 1) * m0
        + (6 * s - 6 * s2) * p1
        + (3 * s2 - 2 * s) * m1
    ) / h
    acc = ((12 * s - 6) * p0 + (6 * s - 4) * m0 + (6 - 12 * s) * p1 + (6 * s - 2) * m1) / h**2
    return pos, vel, acc


def catmull_rom_position(
    values: np.ndarray, frame_dt: float, times: np.ndarray, tang: np.ndarray | None = None
) -> np.ndarray:
    """The position (S, K) alone of :func:`catmull_rom`, weighting four (S, K) arrays by
    the Hermite basis' four (S, 1) values instead of building every term (a third of the
    work, once per step for forces on every free DOF)."""
    s, p0, p1, m0, m1, _ = _segments(values, frame_dt, times, tang)
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (3 * s2 - 2 * s3) * p1) + (
        s3 - s2
    ) * m1


def _segments(
    values: np.ndarray, frame_dt: float, times: np.ndarray, tang: np.ndarray | None
) -> tuple[np.ndarray, ...]:
    """Each time's position s (S, 1) in its segment, the segment's end values p0, p1 and
    tangents times the frame time m0, m1 (S, K), and the frame time h, s."""
    values = np.asarray(values, dtype=np.float64)
    n = len(values)
    if n < 2:
        raise ValueError(f"trajectory needs at least 2 frames, got {n}")
    h = float(frame_dt)
    if tang is None:
        tang = tangents(values, h)
    u = np.clip(np.asarray(times, dtype=np.float64) / h, 0.0, n - 1)
    k = np.minimum(np.floor(u).astype(np.int64), n - 2)
    s = (u - k)[:, None]
    return s, values[k], values[k + 1], tang[k] * h, tang[k + 1] * h, h
