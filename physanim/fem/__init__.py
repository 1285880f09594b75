"""Viscoelastic tetrahedral FEM dynamics (SPEC section 1, stage 7).

Entry points: ``simulate_problem(problem, params)`` -> ``SimResult`` for a :class:`FemProblem`
(mesh, per-tet materials, boundary conditions), or ``simulate(nodes, tets, materials,
driven_idx, driven_traj, frame_dt, fixed_idx, params)`` from arrays. Lower level:
``build_model`` (K, M, C from an element formulation, ``elements``, and a constitutive law,
``laws``), ``Newmark``, ``CorotationalNewmark``, ``solve_static``. ``simulate_problem``
composes ``boundary`` (driven / fixed nodes, springs), ``actuation`` (active stress: a
per-tet sigma_a added to the law's stress, its nodal forces -sum_e V_e B_e^T sigma_a,e
interpolated between frames like the driven motion), ``kinematics`` (linear / corotational),
``stepping`` (adaptive Newmark between frames) and ``monitors`` (energy, stress, inversion per
frame). ``inverse``: the actuation with which the static FEM reproduces observed motion.
``hyperelastic``: a large-strain law (isochoric neo-Hookean, averaged nodal pressure on ln J,
the actuation as an active stress in the material frame or an active strain) and its static
Newton solve.

Element formulations (``SimulateParams.formulation``), thick-walled cylinder under internal
pressure (plane strain, quarter section, b/a = 2), computed / Lame inner displacement:

    nu      tets   p1 (plain 4-node)   anp (default)
    0.3      864        0.986             0.994
    0.495    288        0.729             0.976
    0.495    864        0.792             0.991
    0.495   3456        0.926             0.998
    0.4999  3456        0.538             0.996

'anp' averages the volumetric strain at nodes (K = K_dev + G^T diag(kappa_n V_n) G, same
DOFs, SPD, no spurious zero-energy modes); the deviatoric viscosity needs no averaging.
"""

from physanim.fem.materials import TetMaterials
from physanim.fem.model import FemModel, build_model
from physanim.fem.params import SimulateParams
from physanim.fem.problem import FemProblem
from physanim.fem.simulate import SimResult, simulate, simulate_problem
from physanim.fem.stepping import SimulationDiverged

__all__ = [
    "FemModel",
    "FemProblem",
    "SimResult",
    "SimulateParams",
    "SimulationDiverged",
    "TetMaterials",
    "build_model",
    "simulate",
    "simulate_problem",
]
