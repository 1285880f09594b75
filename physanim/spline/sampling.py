"""Sample points on a cubic spline by a spacing rule (seed 002, Harada and Nakamae).

Stage 1 gives the samples' relative positions along the curve (fractions of the arc
length from the first to the last data point); stage 2 realises them on the curve by
accurate arc-length inversion, then snaps the last sample to the last data point with
the seed's linear correction in parameter space.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physanim.spline.cubic import Spline


def uniform_parameter(spline: Spline, per_segment: int) -> np.ndarray:
    """Seed's sampling method 1: ``per_segment`` points per segment uniform in the
    parameter, plus the last data point; returns parameters t (k,)."""
    if per_segment < 1:
        raise ValueError(f"per_segment must be >= 1, got {per_segment}")
    knots = spline.real_knots
    a, b = knots[:-1, None], knots[1:, None]
    j = np.arange(per_segment) / per_segment
    return np.append((a + (b - a) * j).ravel(), spline.t_end)


def equal_arc(count: int) -> np.ndarray:
    """Relative positions (count,) in [0, 1] for equal arc-length spacing."""
    if count < 2:
        raise ValueError(f"count must be >= 2, got {count}")
    return np.linspace(0.0, 1.0, count)


def from_increments(increments: Sequence[float] | np.ndarray) -> np.ndarray:
    """Relative positions from a user rule: distances between consecutive samples
    (k,) >= 0, scaled so that first-to-last equals the curve length; returns (k + 1,)."""
    inc = np.asarray(increments, dtype=float)
    if inc.ndim != 1 or len(inc) < 1 or (inc < 0).any() or inc.sum() <= 0:
        raise ValueError("increments must be a 1-D sequence of distances >= 0 with a positive sum")
    cum = np.concatenate([[0.0], np.cumsum(inc)])
    return cum / cum[-1]


def equal_curvature(spline: Spline, count: int) -> np.ndarray:
    """Relative positions (count,) with equal integral of the curvature proxy K ds
    between consecutive samples (slow where curved, fast where straight); the integral is
    the spline's adaptive Q(t), inverted exactly at each target."""
    if count < 2:
        raise ValueError(f"count must be >= 2, got {count}")
    q = spline.curvature
    total = float(q.cumulative[-1])
    if total <= 0:
        return equal_arc(count)  # a straight line: K = 0 everywhere
    t = q.inverse(np.linspace(0.0, total, count))
    fractions = spline.arc_length(t) / spline.length
    fractions[0], fractions[-1] = 0.0, 1.0
    return np.maximum.accumulate(fractions)


def place(spline: Spline, fractions: np.ndarray) -> np.ndarray:
    """Parameters t (m,) of samples at relative arc positions ``fractions`` (m,) in
    [0, 1], with the last sample snapped to the last data point (seed's correction)."""
    f = np.asarray(fractions, dtype=float)
    if f.ndim != 1 or len(f) < 2 or f[0] != 0.0 or (np.diff(f) < 0).any():
        raise ValueError("fractions must be a non-decreasing 1-D array starting at 0")
    t = spline.param_at_arc(f * spline.length)
    t[0] = 0.0
    return t * (spline.t_end / t[-1])


def sample(
    spline: Spline,
    rule: str | Sequence[float] | np.ndarray,
    count: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Samples by ``rule``: "arc", "curvature", "uniform" (``count`` = points per
    segment) or a sequence of relative distances.  Returns (points (m, d), params (m,))."""
    if isinstance(rule, str):
        if rule == "uniform":
            t = uniform_parameter(spline, count or 1)
            return spline(t), t
        if count is None:
            raise ValueError(f"rule {rule!r} needs count (number of samples)")
        if rule == "arc":
            fractions = equal_arc(count)
        elif rule == "curvature":
            fractions = equal_curvature(spline, count)
        else:
            raise ValueError(
                f"rule must be 'arc', 'curvature', 'uniform' or increments, got {rule!r}"
            )
    else:
        fractions = from_increments(rule)
    t = place(spline, fractions)
    return spline(t), t
