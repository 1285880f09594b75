"""Articulated-figure dynamics: figures, inverse/forward dynamics, passive motion, keyframes."""

from physanim.dynamics.figure import Figure, FigureError, LinkSpec
from physanim.dynamics.kinematics import (
    Kinematics,
    capsule_segments,
    center_of_mass,
    forward_kinematics,
    link_coms,
)
from physanim.dynamics.passive import StepResult, passive_step, simulate_passive
from physanim.dynamics.rigid import (
    GRAVITY,
    bias_forces,
    forward_dynamics,
    inverse_dynamics,
    mass_matrix,
    mechanical_energy,
    solve_with_known,
)

__all__ = [
    "GRAVITY",
    "Figure",
    "FigureError",
    "Kinematics",
    "LinkSpec",
    "StepResult",
    "bias_forces",
    "capsule_segments",
    "center_of_mass",
    "forward_dynamics",
    "forward_kinematics",
    "inverse_dynamics",
    "link_coms",
    "mass_matrix",
    "mechanical_energy",
    "passive_step",
    "simulate_passive",
    "solve_with_known",
]
