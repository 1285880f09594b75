"""Move an object (e.g. a keyframe figure's root) along a spline with a timing rule."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physanim.spline.cubic import natural_spline
from physanim.spline.sampling import sample


def path_positions(
    points: np.ndarray,
    frames: int,
    rule: str | Sequence[float] | np.ndarray = "arc",
    *,
    extra_point: str | np.ndarray | None = "reflect",
) -> np.ndarray:
    """Positions (frames, d) m, one per frame, along the natural spline through
    ``points`` (n, d) m: ``rule`` "arc" (constant speed), "curvature" (slow in bends) or
    frames - 1 relative distances (e.g. an ease-in/ease-out profile)."""
    spline = natural_spline(points, extra_point=extra_point)
    if isinstance(rule, str):
        if rule == "uniform":
            raise ValueError("rule 'uniform' has no per-frame count; use 'arc' or 'curvature'")
        return sample(spline, rule, frames)[0]
    if len(rule) != frames - 1:
        raise ValueError(f"rule: need frames - 1 = {frames - 1} distances, got {len(rule)}")
    return sample(spline, rule)[0]
