"""Temporal smoothing of landmark tracks (T, ...) with gaps (NaN): One-Euro or Kalman RTS."""

from __future__ import annotations

import numpy as np


def one_euro(
    x: np.ndarray, fps: float, min_cutoff: float, beta: float, d_cutoff: float = 1.0
) -> np.ndarray:
    """One-Euro filter (Casiez et al. 2012) along axis 0 of ``x`` (T, ...), causal.

    ``fps`` frames/s; ``min_cutoff`` Hz; ``beta`` s per unit of x (speed gain of the cutoff);
    NaN samples stay NaN and restart the filter of that channel.
    """
    out = np.full_like(x, np.nan, dtype=np.float64)
    dt = 1.0 / fps

    def alpha(cutoff: np.ndarray | float) -> np.ndarray:
        tau = 1.0 / (2.0 * np.pi * cutoff)
        return 1.0 / (1.0 + tau / dt)

    prev = np.full(x.shape[1:], np.nan)
    dprev = np.zeros(x.shape[1:])
    for t in range(len(x)):
        cur = x[t]
        fresh = ~np.isfinite(prev)
        dx = np.where(fresh, 0.0, (cur - prev) / dt)
        dprev = np.where(fresh, 0.0, dprev + alpha(d_cutoff) * (dx - dprev))
        a = alpha(min_cutoff + beta * np.abs(dprev))
        prev = np.where(fresh, cur, prev + a * (cur - prev))
        out[t] = prev
        dprev = np.where(np.isfinite(cur), dprev, 0.0)
        prev = np.where(np.isfinite(cur), prev, np.nan)
    return out


def kalman_rts(x: np.ndarray, fps: float, accel_std: float, meas_std: float) -> np.ndarray:
    """Constant-velocity Kalman filter + Rauch-Tung-Striebel smoother along axis 0 of ``x``.

    ``x`` (T, ...) with independent channels; ``accel_std`` white-acceleration std (units/s^2),
    ``meas_std`` measurement std (units). Offline and zero-lag. NaN samples are treated as
    missing (predicted through) but stay NaN in the output, so gaps are never filled.
    """
    shape = x.shape
    z = x.reshape(len(x), -1).astype(np.float64)
    n_t, n_c = z.shape
    dt = 1.0 / fps
    f = np.array([[1.0, dt], [0.0, 1.0]])
    q = accel_std**2 * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    r = meas_std**2
    xs = np.zeros((n_t, n_c, 2))
    ps = np.zeros((n_t, n_c, 2, 2))
    xp_all = np.zeros_like(xs)
    pp_all = np.zeros_like(ps)
    state = np.zeros((n_c, 2))
    cov = np.broadcast_to(np.diag([1e6, 1e6]), (n_c, 2, 2)).copy()
    for t in range(n_t):
        xp = state @ f.T if t else state
        pp = f @ cov @ f.T + q if t else cov
        obs = np.isfinite(z[t])
        s = pp[:, 0, 0] + r
        k = pp[:, :, 0] / s[:, None]
        innov = np.where(obs, np.nan_to_num(z[t]) - xp[:, 0], 0.0)
        state = xp + np.where(obs[:, None], k * innov[:, None], 0.0)
        upd = pp - k[:, :, None] * pp[:, None, 0, :]
        cov = np.where(obs[:, None, None], upd, pp)
        xs[t], ps[t], xp_all[t], pp_all[t] = state, cov, xp, pp
    for t in range(n_t - 2, -1, -1):
        gain = ps[t] @ f.T @ np.linalg.inv(pp_all[t + 1])
        xs[t] = xs[t] + np.einsum("cij,cj->ci", gain, xs[t + 1] - xp_all[t + 1])
        ps[t] = ps[t] + gain @ (ps[t + 1] - pp_all[t + 1]) @ gain.transpose(0, 2, 1)
    out = xs[:, :, 0]
    out[~np.isfinite(z)] = np.nan
    return out.reshape(shape)
