"""Articulated-figure dynamics: figures, inverse/forward dynamics, passive motion, keyframes.

The names below load on first use (PEP 562), so importing ``physanim.dynamics.params`` (as
planning does) does not compile or import numba.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "Figure": "figure",
    "FigureError": "figure",
    "LinkSpec": "figure",
    "Kinematics": "kinematics",
    "capsule_segments": "kinematics",
    "center_of_mass": "kinematics",
    "forward_kinematics": "kinematics",
    "link_coms": "kinematics",
    "StepResult": "passive",
    "passive_step": "passive",
    "simulate_passive": "passive",
    "GRAVITY": "rigid",
    "bias_forces": "rigid",
    "forward_dynamics": "rigid",
    "inverse_dynamics": "rigid",
    "mass_matrix": "rigid",
    "mechanical_energy": "rigid",
    "solve_with_known": "rigid",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'physanim.dynamics' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"physanim.dynamics.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value
