"""Natural cubic splines and sample placement by spacing rules (seed 002)."""

from physanim.spline.cubic import Spline, natural_spline
from physanim.spline.motion import path_positions, path_samples
from physanim.spline.sampling import (
    equal_arc,
    equal_curvature,
    from_increments,
    place,
    sample,
    uniform_parameter,
)

__all__ = [
    "Spline",
    "equal_arc",
    "equal_curvature",
    "from_increments",
    "natural_spline",
    "path_positions",
    "path_samples",
    "place",
    "sample",
    "uniform_parameter",
]
