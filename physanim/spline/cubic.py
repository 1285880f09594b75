"""Natural parametric cubic spline through 2-D or 3-D points, with accurate arc length.

The parameter is the cumulative chord length (m), as in Rogers and Adams (seed 002's
reference [1]).  Arc length is integrated by Gauss-Legendre quadrature on each knot
interval and inverted by safeguarded Newton iteration (not the seed's linearised step).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


@dataclass(frozen=True)
class Spline:
    """Natural cubic spline P(t), t in [0, t_end] (m of chord length).

    ``curve``: scipy CubicSpline over all data points (including an optional extra
    point past the end); ``t_end``: parameter of the last real data point; ``knots``
    (k,) parameters of all data points; ``knot_arc`` (k,) arc length at each knot, m.
    """

    curve: CubicSpline
    knots: np.ndarray
    t_end: float
    knot_arc: np.ndarray

    @property
    def length(self) -> float:
        """Arc length from the first to the last real data point, m."""
        return float(self.arc_length(np.array([self.t_end]))[0])

    def __call__(self, t: np.ndarray, nu: int = 0) -> np.ndarray:
        """Points (m, d) (or derivative ``nu``) at parameters t (m,)."""
        return self.curve(np.asarray(t, dtype=float), nu)

    def speed(self, t: np.ndarray) -> np.ndarray:
        """|P'(t)| (dimensionless for the chord-length parameter), shape of t."""
        return np.linalg.norm(self.curve(np.asarray(t, float), 1), axis=-1)

    def curvature_proxy(self, t: np.ndarray) -> np.ndarray:
        """Seed 002 eq 5: K = |P''(t)| = sqrt(x''^2 + y''^2 (+ z''^2)), 1/m."""
        return np.linalg.norm(self.curve(np.asarray(t, float), 2), axis=-1)

    def _segment(self, t: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, len(self.knots) - 2)

    def arc_length(self, t: np.ndarray) -> np.ndarray:
        """Arc length s(t) (m,) in m from the first data point to parameters t (m,)."""
        t = np.asarray(t, dtype=float)
        i = self._segment(t)
        a = self.knots[i]
        half = 0.5 * (t - a)
        nodes = a[:, None] + half[:, None] * (1.0 + _GL_X)
        return self.knot_arc[i] + half * (self.speed(nodes) @ _GL_W)

    def param_at_arc(self, s: np.ndarray, *, tol: float = 1e-13, max_iter: int = 60) -> np.ndarray:
        """Parameters t (m,) with s(t) = s for arc lengths s (m,) m (Newton + bisection)."""
        s = np.asarray(s, dtype=float)
        i = np.clip(np.searchsorted(self.knot_arc, s, side="right") - 1, 0, len(self.knots) - 2)
        lo, hi = self.knots[i].copy(), self.knots[i + 1].copy()
        seg = self.knot_arc[i + 1] - self.knot_arc[i]
        frac = np.where(seg > 0, (s - self.knot_arc[i]) / np.where(seg > 0, seg, 1), 0)
        t = lo + frac * (hi - lo)
        for _ in range(max_iter):
            f = self.arc_length(t) - s
            lo = np.where(f < 0, t, lo)
            hi = np.where(f > 0, t, hi)
            v = self.speed(t)
            step = np.where(v > 1e-12, f / np.where(v > 1e-12, v, 1), np.inf)
            new = t - step
            bad = ~((new > lo) & (new < hi))
            new = np.where(bad, 0.5 * (lo + hi), new)
            done = np.abs(new - t) < tol * max(1.0, self.t_end)
            t = new
            if done.all():
                break
        return t


def natural_spline(points: np.ndarray, *, extra_point: str | np.ndarray | None = None) -> Spline:
    """Natural cubic spline through ``points`` (n, d), d = 2 or 3, in m.

    ``extra_point``: None; ``"reflect"`` adds P_n + (P_n - P_{n-1}) past the end (seed
    002's drift guard); or an explicit point (d,) (the seed's figure-eight repeats P_2).
    Consecutive duplicate points are rejected (zero chord length).
    """
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) < 3:
        raise ValueError(f"points must have shape (n >= 3, 2 or 3), got {p.shape}")
    if isinstance(extra_point, str):
        if extra_point != "reflect":
            raise ValueError(f"extra_point must be None, 'reflect' or a point, got {extra_point!r}")
        p_all = np.vstack([p, 2 * p[-1] - p[-2]])
    elif extra_point is None:
        p_all = p
    else:
        p_all = np.vstack([p, np.asarray(extra_point, dtype=float).reshape(1, -1)])
    chords = np.linalg.norm(np.diff(p_all, axis=0), axis=1)
    if (chords <= 0).any():
        k = int(np.flatnonzero(chords <= 0)[0])
        raise ValueError(f"points {k} and {k + 1} coincide; consecutive points must differ")
    knots = np.concatenate([[0.0], np.cumsum(chords)])
    curve = CubicSpline(knots, p_all, bc_type="natural")
    a, b = knots[:-1], knots[1:]
    half = 0.5 * (b - a)
    nodes = a[:, None] + half[:, None] * (1.0 + _GL_X)
    seg = half * (np.linalg.norm(curve(nodes, 1), axis=-1) @ _GL_W)
    knot_arc = np.concatenate([[0.0], np.cumsum(seg)])
    return Spline(curve, knots, float(knots[len(p) - 1]), knot_arc)
