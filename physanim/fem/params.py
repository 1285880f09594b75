"""User-tunable parameters of the FEM dynamics (``simulate`` stage)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, SerializeAsAny, field_validator, model_validator

from physanim.fem.laws import KelvinVoigt, MaterialLaw, law_from_config


class ModelParams(BaseModel):
    """How the FEM model is assembled and its linear systems solved: element formulation,
    mass matrix, constitutive law, sparse solver (what ``build_model`` and the inverse
    step read)."""

    model_config = ConfigDict(extra="forbid")

    formulation: Literal["anp", "p1"] = Field(
        "anp",
        description="Element: 'anp' = 4-node tet with averaged nodal pressure (locking-free "
        "volumetric part, default); 'p1' = plain 4-node tet (locks near nu = 0.5, as the seed)",
    )
    mass: Literal["consistent", "lumped"] = Field(
        "consistent", description="Mass matrix: consistent (rho int N^T N dV) or row-sum lumped"
    )
    law: SerializeAsAny[MaterialLaw] = Field(
        default_factory=KelvinVoigt,
        description="constitutive law and its settings: {name: <registered law>, ...}; "
        "'kelvin_voigt' (default) reads E, nu, eta, rho per tet "
        "(physanim.fem.laws: LAWS lists the registered laws)",
    )
    solver: Literal["auto", "pardiso", "cholmod", "superlu", "superlu_colamd"] = Field(
        "auto",
        description="Sparse direct solver. Newmark matrix A_uu: 'auto' = PARDISO (MKL, the "
        "'anp' law's one-ring augmented matrix by LDL^T) when MKL loads, else CHOLMOD "
        "(scikit-sparse) when installed, else SuperLU with MMD(A^T+A) ordering; the inverse "
        "step's static K_uu the same. Previews' static K_uu: 'auto' = CHOLMOD, else SuperLU. "
        "'superlu_colamd' = scipy's default splu (baseline)",
    )

    @field_validator("law", mode="before")
    @classmethod
    def _registered_law(cls, value: object) -> MaterialLaw:
        return law_from_config(value)


class SimulateParams(ModelParams):
    """Parameters of the viscoelastic tetrahedral FEM simulation."""

    model_config = ConfigDict(extra="forbid")

    dt: float = Field(
        1e-3,
        gt=0.0,
        le=0.1,
        description="Newmark time step, s: with stepping 'fixed' each capture frame is split "
        "into ceil(frame_dt / dt) equal substeps; with 'adaptive' the smallest step allowed",
    )
    stepping: Literal["adaptive", "fixed"] = Field(
        "adaptive",
        description="'adaptive': each frame takes n equal substeps (n = 1, 2, 4, ..., at most the "
        "'fixed' count), its error estimated by error_estimate; a frame over error_tol_mm is "
        "redone with twice the substeps, a frame far below it lets the next one try half; "
        "'fixed': ceil(frame_dt / dt) substeps in every frame (the reference)",
    )
    error_estimate: Literal["acceleration", "doubling"] = Field(
        "acceleration",
        description="adaptive stepping's error estimate of a frame: 'acceleration' = "
        "Zienkiewicz-Xie's h^2/12 |a_(k+1) - a_k| over the frame's substeps (between "
        "substep-centred accelerations, blind to stiff modes' Nyquist ringing), filtered through "
        "the step's matrix and including the driven nodes' path between the substeps (one "
        "more column per frame; at the coarsest step size up to 8 frames' columns are solved "
        "together, the run rewound to a frame found over the tolerance); 'doubling' = the "
        "frame also computed in half the substeps from the same state, |d_2n - d_n| / 3 "
        "(Richardson; half again as many solves and a second factorisation)",
    )
    error_tol_mm: float = Field(
        0.05,
        gt=0.0,
        le=10.0,
        description="adaptive stepping: largest estimated local error of a frame's "
        "displacements (any DOF) from its integration, mm (0.05: the demo within 0.5 % of its "
        "peak displacement against dt = 0.5 ms, benchmarks/bench_fem.py)",
    )
    factor_cache: int = Field(
        4,
        ge=2,
        le=16,
        description="adaptive stepping: Newmark matrices factorised at distinct step sizes "
        "kept in memory (about 60 MiB each on the demo); the least recently used goes first",
    )
    precision: Literal["float32", "float64", "mixed"] = Field(
        "float32",
        description="Newmark factor: 'float32', single precision (PARDISO: factor and sweeps, "
        "1.6x faster solves than float64, each step off by ~1e-7 relative; CHOLMOD: the "
        "factor stored in float32 and swept in float64, each step exact for a stiffness within "
        "1e-7 relative; SuperLU stays float64), 'float64', or 'mixed': float32 with each "
        "solve refined once with the float64 matrix",
    )
    corotational: bool = Field(
        False, description="Corotational (stiffness-warping) elasticity for large rotations"
    )
    energy_blowup_factor: float = Field(
        1e3,
        gt=1.0,
        description="Stop when the mechanical energy (J) exceeds this factor times the larger "
        "of its past maximum and the driving energy scale (dimensionless)",
    )
    corot_rtol: float = Field(
        1e-8,
        gt=0.0,
        lt=1.0,
        description="Relative residual tolerance of the corotational PCG solve (dimensionless)",
    )
    corot_max_iter: int = Field(
        100, ge=1, le=10_000, description="Iteration cap of the corotational PCG solve"
    )

    @model_validator(mode="before")
    @classmethod
    def _viscosity_moved(cls, data: object) -> object:
        if isinstance(data, dict) and "viscosity" in data:
            raise ValueError(
                "simulate.viscosity moved to the law's settings: law: {name: kelvin_voigt, "
                f"viscosity_form: {data['viscosity']}}}"
            )
        return data
