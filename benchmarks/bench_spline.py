"""Spline spacing: time to place 1000 equal-arc and equal-curvature samples on a smooth
curve, and the worst spacing error on a hairpin, for the adaptive integrals against the
fixed-rule scheme they replaced (24-point Gauss per knot interval; the curvature integral
interpolated on a 64-point grid per interval), measured side by side in the same run.
Spacing errors are checked with scipy's adaptive quadrature (QUADPACK).

Run: .venv/bin/python benchmarks/bench_spline.py
"""

from __future__ import annotations

import time

import numpy as np
from results import Table, describe, record  # benchmarks/results.py, beside this script
from scipy.integrate import quad

from physanim.spline import Spline, natural_spline, sample

_X24, _W24 = np.polynomial.legendre.leggauss(24)


class FixedRule:
    """The replaced scheme: fixed 24-point Gauss-Legendre arc length per knot interval,
    inverted by safeguarded Newton; curvature integral on a 64-point grid per interval."""

    def __init__(self, sp: Spline) -> None:
        self.sp = sp
        a, b = sp.knots[:-1], sp.knots[1:]
        self.knot_arc = np.concatenate([[0.0], np.cumsum(self._gauss(sp.speed, a, b))])

    @staticmethod
    def _gauss(f, a, b):
        half = 0.5 * (b - a)
        return half * (f(a[:, None] + half[:, None] * (1.0 + _X24)) @ _W24)

    def arc(self, t: np.ndarray) -> np.ndarray:
        k = self.sp.knots
        i = np.clip(np.searchsorted(k, t, side="right") - 1, 0, len(k) - 2)
        return self.knot_arc[i] + self._gauss(self.sp.speed, k[i], t)

    def param_at_arc(self, s: np.ndarray) -> np.ndarray:
        k, ka = self.sp.knots, self.knot_arc
        i = np.clip(np.searchsorted(ka, s, side="right") - 1, 0, len(k) - 2)
        lo, hi = k[i].copy(), k[i + 1].copy()
        t = lo + (s - ka[i]) / (ka[i + 1] - ka[i]) * (hi - lo)
        for _ in range(60):
            f = self.arc(t) - s
            lo, hi = np.where(f < 0, t, lo), np.where(f > 0, t, hi)
            new = t - f / np.maximum(self.sp.speed(t), 1e-300)
            new = np.where((new > lo) & (new < hi), new, 0.5 * (lo + hi))
            done = np.abs(new - t) < 1e-13 * max(1.0, self.sp.t_end)
            t = new
            if done.all():
                break
        return t

    def sample(self, rule: str, count: int) -> np.ndarray:
        sp, length = self.sp, self.arc(np.array([self.sp.t_end]))[0]
        if rule == "arc":
            fractions = np.linspace(0.0, 1.0, count)
        else:
            knots = sp.real_knots
            t = np.unique(
                np.concatenate(
                    [np.linspace(a, b, 65) for a, b in zip(knots[:-1], knots[1:], strict=True)]
                )
            )
            q = np.concatenate([[0.0], np.cumsum(self._gauss(sp.curvature_density, t[:-1], t[1:]))])
            s = np.concatenate([[0.0], np.cumsum(self._gauss(sp.speed, t[:-1], t[1:]))])
            fractions = np.interp(np.linspace(0.0, q[-1], count), q, s) / s[-1]
        t = self.param_at_arc(fractions * length)
        return t * (sp.t_end / t[-1])


def _spacing_error(sp: Spline, t: np.ndarray, rule: str) -> float:
    """Largest |gap / mean gap - 1| of the arc (or curvature) integral between samples t."""
    f = sp.speed if rule == "arc" else sp.curvature_density
    gaps = np.array(
        [
            quad(lambda x: f(np.array([x]))[0], a, b, epsabs=1e-14, epsrel=1e-12, limit=500)[0]
            for a, b in zip(t[:-1], t[1:], strict=True)
        ]
    )
    return float(np.abs(gaps / gaps.mean() - 1).max())


def _median_ms(fn, reps: int = 15) -> float:
    fn()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e3


def main() -> None:
    u = np.linspace(0.0, 2.0 * np.pi, 12)
    smooth = np.c_[np.cos(u), 0.5 * np.sin(2.0 * u)]
    hairpin = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.02]])
    print(f"{'rule':10s} {'adaptive':>10s} {'fixed rule':>11s}   1000 samples, smooth curve")
    timing, errors = [], []
    for rule in ("arc", "curvature"):
        ours = _median_ms(lambda r=rule: sample(natural_spline(smooth), r, 1000))
        old = _median_ms(lambda r=rule: FixedRule(natural_spline(smooth)).sample(r, 1000))
        print(f"{rule:10s} {ours:7.2f} ms {old:8.2f} ms")
        timing.append([rule, ours, old])
    sp = natural_spline(hairpin)
    print(f"{'rule':10s} {'adaptive':>10s} {'fixed rule':>11s}   worst spacing error, hairpin")
    for rule in ("arc", "curvature"):
        ours = _spacing_error(sp, sample(sp, rule, 21)[1], rule)
        old = _spacing_error(sp, FixedRule(sp).sample(rule, 21), rule)
        print(f"{rule:10s} {100 * ours:9.2e}% {100 * old:9.2e}%")
        errors.append([rule, 100 * ours, 100 * old])
    record(
        "bench_spline",
        [
            Table(
                "1000 samples, smooth curve (medians of 15)",
                ["rule", "adaptive_ms", "fixed_rule_ms"],
                timing,
            ),
            Table(
                "worst spacing error, hairpin (QUADPACK)",
                ["rule", "adaptive_error_pct", "fixed_rule_error_pct"],
                errors,
            ),
        ],
        **describe(__doc__, "bench_spline"),
        headline={"arc_ms": timing[0][1], "curvature_ms": timing[1][1]},
    )


if __name__ == "__main__":
    main()
