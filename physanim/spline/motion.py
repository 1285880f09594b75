"""Move an object (e.g. a keyframe figure's root) along a spline with a timing rule."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physanim.spline.cubic import Spline, natural_spline
from physanim.spline.sampling import sample

Rule = str | Sequence[float] | np.ndarray


def path_samples(
    points: np.ndarray,
    frames: int,
    rule: Rule = "arc",
    *,
    extra_point: str | np.ndarray | None = "reflect",
) -> tuple[Spline, np.ndarray]:
    """The natural spline through ``points`` (n, d) m and the parameters (frames,) of one
    sample per frame: ``rule`` "uniform" (equal parameter steps, i.e. equal chord-length
    parameter per frame: seed 002's method 1), "arc" (constant speed), "curvature" (slow in
    bends) or frames - 1 relative distances (e.g. an ease-in/ease-out profile).  The first
    and last samples sit on the first and last points (with ``extra_point="reflect"``, the
    seed's guard against the end drifting)."""
    if frames < 2:
        raise ValueError(f"a path needs at least 2 frames, got {frames}")
    spline = natural_spline(points, extra_point=extra_point)
    if isinstance(rule, str):
        if rule == "uniform":
            return spline, np.linspace(0.0, spline.t_end, frames)
        return spline, sample(spline, rule, frames)[1]
    if len(rule) != frames - 1:
        raise ValueError(f"rule: need frames - 1 = {frames - 1} distances, got {len(rule)}")
    return spline, sample(spline, rule)[1]


def path_positions(
    points: np.ndarray,
    frames: int,
    rule: Rule = "arc",
    *,
    extra_point: str | np.ndarray | None = "reflect",
) -> np.ndarray:
    """Positions (frames, d) m, one per frame, along the path (see :func:`path_samples`)."""
    spline, t = path_samples(points, frames, rule, extra_point=extra_point)
    return spline(t)
