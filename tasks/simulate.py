"""Stage ``simulate``: viscoelastic FEM of the tissue, driven by the tracked face.

The boundary conditions come from the library (``physanim.face.drive``): skull nodes fixed,
mandible nodes turned by the jaw rotation estimated from the tracked landmarks, and the skin
pulled by landmark springs (default), by the kinematic scan, or prescribed at single nodes (the
seed, ``configs/drives/seed.yaml``).  Outputs at the capture frame rate.
"""

from __future__ import annotations

from typing import Any

from pydantic import ConfigDict, Field

from physanim.face.params import DriveParams, JawParams
from physanim.fem.params import SimulateParams
from physanim.pipeline import StageContext, StageSpec


class SimulateStageParams(SimulateParams):
    """FEM settings plus how the tracked face drives the tissue."""

    model_config = ConfigDict(extra="forbid")
    drive: DriveParams = Field(default_factory=DriveParams, description="skin drive")
    jaw: JawParams = Field(default_factory=JawParams, description="mandible motion")


def simulate_inputs(
    tracked: Any, aligned: Any, mesh: Any, mats: Any, params: SimulateStageParams
) -> tuple[dict[str, Any], Any]:
    """Arguments of ``physanim.fem.simulate`` from the track, align, tetra and materials
    outputs, and the :class:`~physanim.face.drive.FaceDrive` they came from."""
    import numpy as np

    from physanim.face.drive import (
        estimate_face_jaw,
        face_drive,
        fill_gaps,
        head_frame,
        kinematic_targets,
    )
    from physanim.fem.materials import TetMaterials
    from physanim.mesh.seam import MouthLine, bind_across_seam

    names = list(tracked.attrs["names"])
    rest = tracked["template"][...]
    traj, _ = fill_gaps(head_frame(tracked["points"][...], tracked["head_pose"][...]))
    motion = traj - traj[:1]  # displacements from the reference (first) frame
    mouth = MouthLine(aligned["mouth_line"][...], float(aligned.attrs["lip_band_m"]))
    nodes, tets = mesh["nodes"][...], mesh["tets"][...]
    skin, bone, side = mesh["skin"][...], mesh["bone"][...], mesh["side"][...]
    jaw = None
    if params.jaw.enabled:
        features = list(aligned.attrs["landmark_names"])
        pronasale = aligned["landmarks"][features.index("pronasale")]
        jaw, _ = estimate_face_jaw(
            names, rest, motion, mouth, pronasale, params.jaw, aligned["motion"][...]
        )
    targets = None
    if params.drive.mode == "kinematic":
        free = np.nonzero(skin & ~bone)[0]
        binding = bind_across_seam(
            nodes[free], side[free], aligned["scan_vertices"][...], aligned["scan_faces"][...],
            mouth,
        )  # fmt: skip
        targets = kinematic_targets(
            binding, aligned["scan_faces"][...], aligned["kinematic"][...].astype(np.float64)
        )
    drive = face_drive(
        nodes, tets, skin, bone, side, mesh["skin_anchor"][...], mouth, jaw, names, rest,
        motion, params.drive, params.jaw.blend_m, targets,
    )  # fmt: skip
    args = {
        "nodes": nodes,
        "tets": tets,
        "materials": TetMaterials(*(mats[k][...] for k in ("E", "nu", "eta", "rho"))),
        "driven_idx": drive.prescribed,
        "driven_traj": drive.prescribed_traj,
        "frame_dt": 1.0 / float(aligned.attrs["fps"]),
        "springs": drive.springs,
    }
    return args, drive


def compute(ctx: StageContext) -> None:
    """displacements (T,n,3) float32 m, energies (T,) J, von Mises max and 99th percentile
    (T,) Pa, the jaw's angle (T,) rad / pivot / axis, the driven and spring nodes."""
    import numpy as np

    from physanim.fem.linsolve import blas_in_use
    from physanim.fem.simulate import hot_spot_ratio, simulate

    params: SimulateStageParams = ctx.params  # type: ignore[assignment]
    args, drive = simulate_inputs(
        ctx.input("track"), ctx.input("align"), ctx.input("tetra"), ctx.input("materials"),
        params,
    )  # fmt: skip
    result = simulate(**args, params=params, progress=ctx.progress("simulate"))
    ctx.write_record(result)
    ctx.write("driven_nodes", drive.prescribed)
    ctx.write("bone_nodes", drive.bone)
    ctx.write("mandible_weight", drive.mandible_weight)
    springs = drive.springs
    ctx.write("spring_nodes", springs.nodes if springs else np.zeros(0, np.int64))
    ctx.write("spring_stiffness", springs.stiffness if springs else np.zeros(0))
    n_skin = int(ctx.input("tetra")["skin"][...].sum())
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
        ctx.write_record(drive.jaw, prefix="jaw")
        summary["jaw_max_angle_deg"] = round(float(np.degrees(drive.jaw.angle.max())), 3)
        summary["jaw_pivot_mm"] = [round(float(x) * 1e3, 2) for x in drive.jaw.pivot]
    ctx.out.attrs["driving_landmarks"] = drive.landmarks
    if drive.warnings:
        summary["warnings"] = drive.warnings
    ctx.summary.update(summary)


SPEC = StageSpec(
    name="simulate",
    upstream=("track", "align", "tetra", "materials"),
    params=SimulateStageParams,
    version="3",
    compute=compute,
    doc="viscoelastic FEM (Newmark); skull fixed, mandible turned by the estimated jaw, skin "
    "pulled by the tracked landmarks",
)
