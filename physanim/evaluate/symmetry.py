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


def lag_frames(driver: NDArray[np.floating], follower: NDArray[np.floating], max_lag: int) -> int:
    """Lag (frames, >= 0 when ``follower`` trails ``driver``) maximising their correlation.

    driver, follower: (T,) curves, e.g. mean displacement of driven and of free skin nodes;
    lags beyond T - 1 frames are not searched.
    """
    a = driver - driver.mean()
    b = follower - follower.mean()
    n = len(a)
    max_lag = min(max_lag, n - 1)
    lags = np.arange(-max_lag, max_lag + 1)
    scores = [
        float(np.dot(a[max(0, -k) : n - max(0, k)], b[max(0, k) : n - max(0, -k)])) for k in lags
    ]
    return int(lags[int(np.argmax(scores))])
