"""Stage ``simulate``: viscoelastic FEM of the tissue, driven by the tracked face.

The boundary conditions come from the library (``physanim.face.drive``): skull nodes fixed,
mandible nodes turned by the jaw rotation estimated from the tracked landmarks, and the skin
moved by the active stress the ``actuate`` stage fitted to the capture (``drive.mode:
actuation``, the default, scaled per face region by ``drive.actuation_scale``), pulled by
landmark springs (``configs/drives/landmarks.yaml``), by the kinematic scan, or prescribed at
single nodes (the seed, ``configs/drives/seed.yaml``), chosen by
``physanim.face.performance``. They, the actuation and the tissue mesh and materials form a
:class:`~physanim.fem.problem.FemProblem`, solved by ``physanim.fem.simulate`` at the capture
frame rate, or with ``simulate.reduced.enabled`` in a reduced (POD) basis built from a full run
of a basis material (``physanim.fem.preview``), for fast previews of material edits.
Version history: CHANGELOG.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import (
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    model_serializer,
    model_validator,
)

from physanim.face.drive import FaceDrive
from physanim.face.jaw import JawMotion
from physanim.face.params import ActuationParams, DriveParams, JawParams
from physanim.fem.params import SimulateParams
from physanim.fem.preview import ReducedParams
from physanim.fem.problem import FemProblem
from physanim.fem.simulate import SimResult
from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.actuation import ActuateOutput, stage_drive
from tasks.align import AlignOutput
from tasks.fit import FitOutput
from tasks.materials import MaterialsOutput
from tasks.tetra import TetraOutput
from tasks.track import TrackOutput


class SimulateStageParams(SimulateParams):
    """FEM settings plus how the tracked face drives the tissue."""

    model_config = ConfigDict(extra="forbid")
    drive: DriveParams = Field(default_factory=DriveParams, description="skin drive")
    jaw: JawParams = Field(default_factory=JawParams, description="mandible motion")
    actuation: ActuationParams = Field(
        default_factory=ActuationParams, description="the inverse step (stage 'actuate')"
    )
    reduced: ReducedParams = Field(
        default_factory=ReducedParams, description="reduced (POD) preview of material edits"
    )

    @model_validator(mode="after")
    def _preview_is_linear(self) -> SimulateStageParams:
        if self.reduced.enabled and self.corotational:
            raise ValueError(
                "reduced.enabled: the reduced preview is linear; set corotational: false"
            )
        if self.drive.mode == "actuation" and self.corotational:
            raise ValueError("drive.mode actuation: the active stress is linear; set "
                             "corotational: false")  # fmt: skip
        return self

    @model_serializer(mode="wrap")
    def _without_disabled_preview(self, handler: SerializerFunctionWrapHandler) -> dict:
        """A disabled preview changes nothing: left out of the dump, so of the stage key."""
        data = handler(self)
        if not self.reduced.enabled:
            data.pop("reduced", None)
        return data


@dataclass(frozen=True, kw_only=True)
class SimulateOutput(SimResult, StageOutput):
    """The tissue's motion at the capture frame rate (T frames, n nodes, m tets): every field
    of :class:`~physanim.fem.simulate.SimResult` (displacements (T, n, 3) float32 m, energies
    J, von Mises max and 99th percentile Pa, inverted tets, steps, timings s) plus the boundary
    conditions: ``driven_nodes`` (D,) prescribed, ``bone_nodes`` (B,), ``mandible_weight`` (B,),
    ``spring_nodes`` (S,) with ``spring_stiffness`` (S,) N/m, ``driving_landmarks`` and the
    ``jaw`` (None: disabled).
    """

    driven_nodes: np.ndarray
    bone_nodes: np.ndarray
    mandible_weight: np.ndarray
    spring_nodes: np.ndarray
    spring_stiffness: np.ndarray
    driving_landmarks: list[str]
    jaw: JawMotion | None = None


def simulate_inputs(
    track: TrackOutput,
    fit: FitOutput,
    align: AlignOutput,
    tetra: TetraOutput,
    materials: MaterialsOutput,
    actuate: ActuateOutput,
    params: SimulateStageParams,
) -> tuple[FemProblem, FaceDrive]:
    """The FEM problem of the track, align, tetra, materials and (in the 'actuation' drive)
    actuate outputs (a gesture weighted by the fit's action units, ``drive.
    actuation_scale_with``), and the :class:`~physanim.face.drive.FaceDrive` its boundary
    conditions came from."""
    drive = stage_drive(track, align, tetra, params.drive, params.jaw)
    problem = FemProblem.driven(
        tetra.nodes, tetra.tets, materials.materials(), drive.prescribed,
        drive.prescribed_traj, 1.0 / float(track.fps), springs=drive.springs,
    )  # fmt: skip
    if params.drive.mode == "actuation":
        activity = None
        if params.drive.actuation_scale_with:
            from physanim.face.gesture import unit_activity

            activity = unit_activity(
                fit.au, fit.au_names, params.drive.actuation_scale_with,
                params.drive.actuation_scale_full_span,
            )  # fmt: skip
        problem = problem.with_actuation(actuate.actuation(tetra, params.drive, activity))
    return problem, drive


def compute(
    params: SimulateStageParams,
    track: TrackOutput,
    fit: FitOutput,
    align: AlignOutput,
    tetra: TetraOutput,
    materials: MaterialsOutput,
    actuate: ActuateOutput,
    ctx: StageContext[SimulateStageParams],
) -> SimulateOutput:
    """displacements (T,n,3) float32 m, energies (T,) J, von Mises max and 99th percentile
    (T,) Pa, the jaw's angle (T,) rad / pivot / axis, the driven and spring nodes."""
    from physanim.face.performance import performance_summary
    from physanim.fem.simulate import simulate_problem

    problem, drive = simulate_inputs(track, fit, align, tetra, materials, actuate, params)
    if params.reduced.enabled:
        from physanim.fem.preview import preview

        result, reduced_summary = preview(
            problem, materials.tet_labels, materials.region_names, params, params.reduced,
            ctx.dataset.run_dir / "cache" / "reduced-basis", ctx.progress("simulate (reduced)"),
        )  # fmt: skip
    else:
        result = simulate_problem(problem, params, ctx.progress("simulate"))
    summary = performance_summary(result, drive, int(tetra.skin.sum()), params, params.drive.mode)
    if problem.actuation is not None:
        summary["actuation"] = {
            "patches": problem.actuation.basis.n_patches,
            "scale": params.drive.actuation_scale,
            **({"scale_with": params.drive.actuation_scale_with}
               if params.drive.actuation_scale_with else {}),
        }  # fmt: skip
    if params.reduced.enabled:
        summary.update(
            stepping="reduced (POD preview)",
            check_steps=0,
            seconds=reduced_summary.pop("seconds"),
            reduced=reduced_summary,
        )
        for k in ("frames_over_tolerance", "solver_threads", "blas"):
            summary.pop(k)
    springs = drive.springs
    return SimulateOutput(
        **vars(result),  # the SimResult fields
        driven_nodes=drive.prescribed,
        bone_nodes=drive.bone,
        mandible_weight=drive.mandible_weight,
        spring_nodes=springs.nodes if springs else np.zeros(0, np.int64),
        spring_stiffness=springs.stiffness if springs else np.zeros(0),
        driving_landmarks=list(drive.landmarks),
        jaw=drive.jaw,
        summary=summary,
    )


SPEC = StageSpec.typed(
    "simulate",
    compute,
    version="12",
    doc="viscoelastic FEM (Newmark); skull fixed, mandible turned by the estimated jaw, skin "
    "moved by the fitted actuation (default) or pulled by the tracked landmarks (drive.mode)",
)
