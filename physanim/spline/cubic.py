"""Natural parametric cubic spline through 2-D or 3-D points, with error-controlled integrals.

The parameter is the cumulative chord length (m), as in Rogers and Adams (seed 002's
reference [1]).  The arc length s(t) = int |P'| dt and the curvature integral
Q(t) = int K |P'| dt (K = |P''|, seed eq 5) are integrated adaptively: each knot interval is
bisected until a Gauss-Legendre rule on a piece agrees with the same rule on its two halves
to a relative tolerance of the whole integral, so a speed that nearly vanishes (hairpins,
near-cusps) is followed as closely as a straight stretch.  Both integrals are inverted by
safeguarded Newton iteration inside their pieces (not the seed's linearised step).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.interpolate import CubicSpline

_GL_X, _GL_W = np.polynomial.legendre.leggauss(10)
REL_TOL = 1e-12  # error of an integral over the whole curve, relative to its total
MAX_LEVELS = 60  # bisection levels; a piece still failing then is ~1e-18 of the interval


def _gauss(f: Callable[[np.ndarray], np.ndarray], a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Gauss-Legendre (10 points) integrals of f over [a, b] (elementwise, any shape)."""
    half = 0.5 * (b - a)
    nodes = a[..., None] + half[..., None] * (1.0 + _GL_X)
    return half * (f(nodes) @ _GL_W)


@dataclass(frozen=True)
class AdaptiveIntegral:
    """F(t) = int_0^t f dt of a non-negative integrand f, in pieces on which the 10-point
    Gauss rule is resolved.

    ``breaks`` (p + 1,) piece boundaries (parameter units); ``cumulative`` (p + 1,) F at
    them; ``integrand`` f of an array of parameters (any shape).
    """

    breaks: np.ndarray
    cumulative: np.ndarray
    integrand: Callable[[np.ndarray], np.ndarray]

    @classmethod
    def build(
        cls,
        integrand: Callable[[np.ndarray], np.ndarray],
        knots: np.ndarray,
        rel_tol: float = REL_TOL,
    ) -> AdaptiveIntegral:
        """Bisect every knot interval until the rule on a piece and on its halves agree to
        ``rel_tol`` times the total, shared out in proportion to the piece's width."""
        lo, hi = knots[:-1], knots[1:]
        span = knots[-1] - knots[0]
        total = float(np.sum(_gauss(integrand, lo, hi)))
        pieces_lo, pieces_hi, values = [], [], []
        for level in range(MAX_LEVELS + 1):
            mid = 0.5 * (lo + hi)
            whole = _gauss(integrand, lo, hi)
            halves = _gauss(integrand, lo, mid) + _gauss(integrand, mid, hi)
            tol = rel_tol * max(total, np.finfo(float).tiny) * (hi - lo) / span
            done = (np.abs(whole - halves) <= tol) | (level == MAX_LEVELS)
            pieces_lo.append(lo[done])
            pieces_hi.append(hi[done])
            values.append(halves[done])
            if done.all():
                break
            lo, hi = (
                np.concatenate([lo[~done], mid[~done]]),
                np.concatenate([mid[~done], hi[~done]]),
            )
        a, b, v = (np.concatenate(x) for x in (pieces_lo, pieces_hi, values))
        order = np.argsort(a)
        breaks = np.append(a[order], b[order][-1])
        return cls(breaks, np.concatenate([[0.0], np.cumsum(v[order])]), integrand)

    def _piece(self, t: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.breaks, t, side="right") - 1, 0, len(self.breaks) - 2)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """F(t) for parameters t (m,) (piece start plus the Gauss rule up to t)."""
        t = np.asarray(t, dtype=float)
        i = self._piece(t)
        return self.cumulative[i] + _gauss(self.integrand, self.breaks[i], t)

    def inverse(self, y: np.ndarray, *, tol: float = 1e-14, max_iter: int = 60) -> np.ndarray:
        """Parameters t (m,) with F(t) = y (m,): Newton steps kept inside a bracket, with
        bisection where a step would leave it (f may vanish inside a piece)."""
        y = np.asarray(y, dtype=float)
        i = np.clip(np.searchsorted(self.cumulative, y, side="right") - 1, 0, len(self.breaks) - 2)
        lo, hi = self.breaks[i].copy(), self.breaks[i + 1].copy()
        width = self.cumulative[i + 1] - self.cumulative[i]
        safe = np.where(width > 0, width, 1.0)
        t = lo + np.where(width > 0, (y - self.cumulative[i]) / safe, 0.0) * (hi - lo)
        scale = tol * max(1.0, float(self.breaks[-1] - self.breaks[0]))
        noise = 8.0 * np.finfo(float).eps * max(float(self.cumulative[-1]), 1e-300)
        for _ in range(max_iter):
            f = self(t) - y
            hit = np.abs(f) <= noise  # F(t) = y to rounding: nothing left to improve
            lo = np.where(f < 0, t, lo)
            hi = np.where(f > 0, t, hi)
            d = self.integrand(t)
            step = np.where(d > 0, f / np.where(d > 0, d, 1.0), np.inf)
            new = t - step
            new = np.where((new > lo) & (new < hi), new, 0.5 * (lo + hi))
            done = hit | (np.abs(new - t) <= scale)
            t = np.where(hit, t, new)
            if done.all():
                break
        return t


@dataclass(frozen=True)
class Spline:
    """Natural cubic spline P(t), t in [0, t_end] (m of chord length).

    ``curve``: scipy CubicSpline over all data points (including an optional extra
    point past the end); ``knots`` (k,) parameters of all data points; ``t_end``: parameter
    of the last real data point; ``arc``: the adaptive arc-length integral s(t), m.
    """

    curve: CubicSpline
    knots: np.ndarray
    t_end: float
    arc: AdaptiveIntegral

    @property
    def length(self) -> float:
        """Arc length from the first to the last real data point, m."""
        return float(self.arc_length(np.array([self.t_end]))[0])

    @property
    def real_knots(self) -> np.ndarray:
        """Parameters (k,) of the real data points (without an extra point past the end)."""
        return self.knots[self.knots <= self.t_end + 1e-12]

    def __call__(self, t: np.ndarray, nu: int = 0) -> np.ndarray:
        """Points (m, d) (or derivative ``nu``) at parameters t (m,)."""
        return self.curve(np.asarray(t, dtype=float), nu)

    def speed(self, t: np.ndarray) -> np.ndarray:
        """|P'(t)| (dimensionless for the chord-length parameter), shape of t."""
        return np.linalg.norm(self.curve(np.asarray(t, float), 1), axis=-1)

    def curvature_proxy(self, t: np.ndarray) -> np.ndarray:
        """Seed 002 eq 5: K = |P''(t)| = sqrt(x''^2 + y''^2 (+ z''^2)), 1/m."""
        return np.linalg.norm(self.curve(np.asarray(t, float), 2), axis=-1)

    def curvature_density(self, t: np.ndarray) -> np.ndarray:
        """K |P'|: the integrand of the curvature integral over the parameter, 1/m."""
        return self.curvature_proxy(t) * self.speed(t)

    def arc_length(self, t: np.ndarray) -> np.ndarray:
        """Arc length s(t) (m,) in m from the first data point to parameters t (m,)."""
        return self.arc(t)

    def param_at_arc(self, s: np.ndarray) -> np.ndarray:
        """Parameters t (m,) with s(t) = s for arc lengths s (m,) m."""
        return self.arc.inverse(s)

    @cached_property
    def curvature(self) -> AdaptiveIntegral:
        """Q(t) = int_0^t K |P'| dt (dimensionless), over the real data points."""
        return AdaptiveIntegral.build(self.curvature_density, self.real_knots)


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

    def speed(t: np.ndarray) -> np.ndarray:
        return np.linalg.norm(curve(t, 1), axis=-1)

    return Spline(curve, knots, float(knots[len(p) - 1]), AdaptiveIntegral.build(speed, knots))
