"""Symmetry cost of seed 004 (SPEC eqs 4.38-4.39) and mouth-corner curves."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from physanim.face.landmarks import SYMMETRY_LANDMARKS

#: floor of |E_L - E_R| inside the log, so a perfectly symmetric frame gives a finite cost
EPS = 1e-12


def side_energy(points: NDArray[np.floating], names: Sequence[str], side: str) -> NDArray:
    """E_side(t) = sum_k (r_k(t) / r_k(t0) - 1), r_k = |landmark k - cheilion| on that side.

    points: (T, K, 3) m, landmark trajectories; names: (K,) feature-point names; side "L"/"R".
    Returns (T,), dimensionless; frame 0 is the reference t0.
    """
    index = {n: i for i, n in enumerate(names)}
    needed = [f"{k}_{side}" for k in ("ch", *SYMMETRY_LANDMARKS)]
    missing = [n for n in needed if n not in index]
    if missing:
        raise ValueError(f"symmetry cost needs landmarks {missing}; got {list(names)}")
    ch = points[:, index[f"ch_{side}"]]
    others = points[:, [index[f"{k}_{side}"] for k in SYMMETRY_LANDMARKS]]
    r = np.linalg.norm(others - ch[:, None, :], axis=-1)  # (T, 4)
    return (r / r[0] - 1.0).sum(axis=1)


def symmetry_cost(
    points: NDArray[np.floating], names: Sequence[str]
) -> tuple[NDArray, NDArray, NDArray]:
    """L_cost(t) = log |E_L(t) - E_R(t)| (natural log), with E_L, E_R; each (T,)."""
    e_l = side_energy(points, names, "L")
    e_r = side_energy(points, names, "R")
    return np.log(np.maximum(np.abs(e_l - e_r), EPS)), e_l, e_r


def displacement_curves(points: NDArray[np.floating]) -> NDArray:
    """|p(t) - p(0)| per landmark: (T, K, 3) m -> (T, K) m."""
    return np.linalg.norm(points - points[:1], axis=-1)


def lag_frames(driver: NDArray[np.floating], follower: NDArray[np.floating], max_lag: int) -> float:
    """Lag (frames, fractional; > 0 when ``follower`` trails ``driver``), both (T,) curves
    (e.g. the mean displacement of driven and of free skin nodes).

    The shift s in [-max_lag, max_lag] (clamped to T - 1) whose ``driver(t - s)`` (a cubic
    spline through the frames) correlates best (Pearson) with ``follower(t)``: first the best
    whole frame k, each over the frames its shift covers (at least half of them), then s in
    [k - 1, k + 1] over the frames that whole bracket covers (a set changing with s would make
    the correlation jump at whole frames), moving the bracket while s lands on its edge. A
    Kelvin-Voigt delay eta / E of a few milliseconds is a fraction of a 30 fps frame."""
    from scipy.interpolate import CubicSpline
    from scipy.optimize import minimize_scalar

    b_all = np.asarray(follower, dtype=np.float64)
    n = len(b_all)
    t = np.arange(n, dtype=np.float64)
    shifted = CubicSpline(t, np.asarray(driver, dtype=np.float64))
    max_lag = min(max_lag, n - 1)

    def correlation(s: float, lo: float, hi: float) -> float:
        inside = (t - hi >= 0) & (t - lo <= n - 1)  # the frames every shift in [lo, hi] covers
        if inside.sum() < max(3, n // 2):
            return -np.inf
        a, b = shifted(t[inside] - s), b_all[inside]
        a, b = a - a.mean(), b - b.mean()
        norm = np.sqrt((a @ a) * (b @ b))
        return float(a @ b / norm) if norm > 0 else 0.0

    whole = np.arange(-max_lag, max_lag + 1)
    k = int(whole[np.argmax([correlation(j, j, j) for j in whole])])
    for _ in range(max_lag + 1):
        lo, hi = max(k - 1.0, -max_lag), min(k + 1.0, float(max_lag))
        s = minimize_scalar(
            lambda x, lo=lo, hi=hi: -correlation(x, lo, hi), bounds=(lo, hi), method="bounded",
            options={"xatol": 1e-4},
        ).x  # fmt: skip
        edge = hi if s > k else lo
        if abs(s - edge) > 1e-3 or edge in (-max_lag, max_lag):
            break
        k = int(edge)
    return float(s)
