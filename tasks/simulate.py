"""Stage ``simulate``: viscoelastic FEM of the tissue, driven by the tracked face.

The boundary conditions come from the library (``physanim.face.drive``): skull nodes fixed,
mandible nodes turned by the jaw rotation estimated from the tracked landmarks, and the skin
pulled by landmark springs (default), by the kinematic scan, or prescribed at single nodes (the
seed, ``configs/drives/seed.yaml``), chosen by ``physanim.face.performance``.  Outputs at the
capture frame rate.

Version 4: the output is declared by :class:`SimulateOutput`; a disabled jaw is stored as a
null ``jaw`` attribute (before: absent).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import ConfigDict, Field

from physanim.face.jaw import JawMotion
from physanim.face.params import DriveParams, JawParams
from physanim.fem.params import SimulateParams
from physanim.pipeline import StageContext, StageSpec
from tasks.align import AlignOutput
from tasks.materials import MaterialsOutput
from tasks.tetra import TetraOutput
from tasks.track import TrackOutput


class SimulateStageParams(SimulateParams):
    """FEM settings plus how the tracked face drives the tissue."""

    model_config = ConfigDict(extra="forbid")
    drive: DriveParams = Field(default_factory=DriveParams, description="skin drive")
    jaw: JawParams = Field(default_factory=JawParams, description="mandible motion")


@dataclass(frozen=True)
class SimulateOutput:
    """The tissue's motion at the capture frame rate (T frames, n nodes, m tets).

    ``displacements`` (T, n, 3) float32 m; ``times`` (T,) s;
    ``kinetic``, ``strain``, ``dissipated`` (T,) J; ``max_von_mises`` and ``p99_von_mises``
    (T,) Pa; ``inverted_count`` (T,), ``inverted_tets`` (K,); ``dt`` s smallest substep,
    ``n_substeps``, ``frame_substeps`` (T,), ``check_steps``, ``frames_over_tolerance``,
    ``solver_threads`` (T,), ``corot_iterations`` (T,) or None, ``timings`` s (see
    ``physanim.fem.simulate.SimResult``); the boundary conditions: ``driven_nodes`` (D,)
    prescribed, ``bone_nodes`` (B,), ``mandible_weight`` (n,), ``spring_nodes`` (S,) with
    ``spring_stiffness`` (S,) N/m, ``driving_landmarks`` and the ``jaw`` (None: disabled).
    """

    displacements: np.ndarray
    times: np.ndarray
    kinetic: np.ndarray
    strain: np.ndarray
    dissipated: np.ndarray
    max_von_mises: np.ndarray
    p99_von_mises: np.ndarray
    inverted_count: np.ndarray
    inverted_tets: np.ndarray
    dt: float
    n_substeps: int
    timings: dict[str, float]
    corot_iterations: np.ndarray | None
    frame_substeps: np.ndarray | None
    solver_threads: np.ndarray | None
    check_steps: int
    frames_over_tolerance: int
    driven_nodes: np.ndarray
    bone_nodes: np.ndarray
    mandible_weight: np.ndarray
    spring_nodes: np.ndarray
    spring_stiffness: np.ndarray
    driving_landmarks: list[str]
    jaw: JawMotion | None = None


def simulate_inputs(
    track: TrackOutput,
    align: AlignOutput,
    tetra: TetraOutput,
    materials: MaterialsOutput,
    params: SimulateStageParams,
) -> tuple[dict[str, Any], Any]:
    """Arguments of ``physanim.fem.simulate`` from the track, align, tetra and materials
    outputs, and the :class:`~physanim.face.drive.FaceDrive` they came from."""
    from physanim.face.performance import landmark_motion, performance_drive
    from physanim.names import name_index

    mouth = align.mouth()
    pronasale = align.landmarks[name_index(align.landmark_names, ["pronasale"])[0]]
    tissue = {k: getattr(tetra, k) for k in ("nodes", "tets", "skin", "bone", "side")}
    drive = performance_drive(
        track.landmark_names, track.template, landmark_motion(track.points, track.head_pose),
        mouth, pronasale, align.motion, {**tissue, "skin_anchor": tetra.skin_anchor},
        (align.scan_vertices, align.scan_faces), lambda: align.kinematic[...],
        params.drive, params.jaw,
    )  # fmt: skip
    args = {
        "nodes": tetra.nodes,
        "tets": tetra.tets,
        "materials": materials.materials(),
        "driven_idx": drive.prescribed,
        "driven_traj": drive.prescribed_traj,
        "frame_dt": 1.0 / float(track.fps),
        "springs": drive.springs,
    }
    return args, drive


def compute(
    params: SimulateStageParams,
    track: TrackOutput,
    align: AlignOutput,
    tetra: TetraOutput,
    materials: MaterialsOutput,
    ctx: StageContext[SimulateStageParams],
) -> SimulateOutput:
    """displacements (T,n,3) float32 m, energies (T,) J, von Mises max and 99th percentile
    (T,) Pa, the jaw's angle (T,) rad / pivot / axis, the driven and spring nodes."""
    from physanim.fem.linsolve import blas_in_use
    from physanim.fem.simulate import hot_spot_ratio, simulate

    args, drive = simulate_inputs(track, align, tetra, materials, params)
    result = simulate(**args, params=params, progress=ctx.progress("simulate"))
    springs = drive.springs
    n_skin = int(tetra.skin.sum())
    summary: dict[str, Any] = {
        "frames": len(result.displacements),
        "dt_s": result.dt,
        "substeps_per_frame": result.n_substeps,
        "stepping": params.stepping,
        "steps": int(result.frame_substeps.sum()),
        "check_steps": result.check_steps,
        "frames_over_tolerance": result.frames_over_tolerance,
        "blas": blas_in_use(),
        "solver_threads": sorted({int(t) for t in result.solver_threads[1:]}),
        "drive": params.drive.mode,
        "driving_landmarks": len(drive.landmarks),
        "spring_node_fraction_of_skin": round(len(springs.nodes) / n_skin, 4) if springs else 0,
        "max_displacement_mm": round(float(np.abs(result.displacements).max()) * 1e3, 3),
        "peak_von_mises_kPa": round(float(result.max_von_mises.max()) / 1e3, 3),
        "peak_to_p99_von_mises": round(hot_spot_ratio(result), 3),
        "inverted_tets": int(len(result.inverted_tets)),
        "seconds": {k: round(v, 3) for k, v in result.timings.items()},
    }
    if drive.jaw is not None:
        summary["jaw_max_angle_deg"] = round(float(np.degrees(drive.jaw.angle.max())), 3)
        summary["jaw_pivot_mm"] = [round(float(x) * 1e3, 2) for x in drive.jaw.pivot]
    if drive.warnings:
        summary["warnings"] = drive.warnings
    ctx.summary.update(summary)
    sim_fields = [f for f in SimulateOutput.__dataclass_fields__ if hasattr(result, f)]
    return SimulateOutput(
        **{f: getattr(result, f) for f in sim_fields},
        driven_nodes=drive.prescribed,
        bone_nodes=drive.bone,
        mandible_weight=drive.mandible_weight,
        spring_nodes=springs.nodes if springs else np.zeros(0, np.int64),
        spring_stiffness=springs.stiffness if springs else np.zeros(0),
        driving_landmarks=list(drive.landmarks),
        jaw=drive.jaw,
    )


SPEC = StageSpec.typed(
    "simulate",
    compute,
    version="4",
    doc="viscoelastic FEM (Newmark); skull fixed, mandible turned by the estimated jaw, skin "
    "pulled by the tracked landmarks",
)
