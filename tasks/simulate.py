"""Stage ``simulate``: viscoelastic FEM of the tissue driven by the tracked feature points.

Landmark skin nodes follow the motion mesh's feature-point displacements (scan frame), bone-side
nodes are fixed, all others are free (SPEC eq 4.37).  Outputs at the capture frame rate.
"""

from __future__ import annotations

from typing import Any

from pydantic import ConfigDict, Field, field_validator

from physanim.face.landmarks import FEATURE_POINTS
from physanim.fem.params import SimulateParams
from physanim.pipeline import StageContext, StageSpec

#: Driven feature points by default: 7 points on the edges of the mimetic muscles (the seed
#: drove its FEM with 7 tracked points; its text does not list them).  The philtrum, nose wings
#: and lower eyelids stay free, so the material decides how they move.
DRIVE = ("ch_L", "ch_R", "cheek_L", "cheek_R", "ex_L", "ex_R", "glabella")


class SimulateStageParams(SimulateParams):
    """FEM settings plus which tracked feature points drive the skin."""

    model_config = ConfigDict(extra="forbid")
    drive: list[str] = Field(
        default_factory=lambda: list(DRIVE), min_length=1, description="driven feature points"
    )

    @field_validator("drive")
    @classmethod
    def _known(cls, v: list[str]) -> list[str]:
        unknown = [n for n in v if n not in FEATURE_POINTS]
        if unknown:
            raise ValueError(f"{unknown} are not feature points; choose from {FEATURE_POINTS}")
        return v


def simulate_inputs(
    aligned: Any, mesh: Any, mats: Any, drive: list[str]
) -> tuple[dict[str, Any], Any, list[str]]:
    """Arguments of ``physanim.fem.simulate`` from the align, tetra and materials outputs.

    Returns (keyword arguments: nodes, tets, materials, driven_idx (first tracked point per
    node), driven_traj (T, n_d, 3) m, frame_dt s, fixed_idx (bone-side nodes not driven);
    skin (N,) bool; names of the n_d driving feature points).
    """
    import numpy as np

    from physanim.fem.materials import TetMaterials

    motion = aligned["motion"][...].astype(np.float64)  # (T, V, 3) scan frame
    names = list(aligned.attrs["landmark_names"])
    missing = [n for n in drive if n not in names]
    if missing:
        raise ValueError(f"simulate.drive: {missing} were not tracked (tracked: {names})")
    rows = np.array([names.index(n) for n in drive])
    lm_vertices = aligned["landmark_vertices"][...][rows]
    nodes, tets = mesh["nodes"][...], mesh["tets"][...]
    driven, first = np.unique(mesh["landmark_node"][...][rows], return_index=True)
    args = {
        "nodes": nodes,
        "tets": tets,
        "materials": TetMaterials(*(mats[k][...] for k in ("E", "nu", "eta", "rho"))),
        "driven_idx": driven,
        "driven_traj": motion[:, lm_vertices[first]] - motion[:1, lm_vertices[first]],
        "frame_dt": 1.0 / float(aligned.attrs["fps"]),
        "fixed_idx": np.nonzero(mesh["bone"][...] & ~np.isin(np.arange(len(nodes)), driven))[0],
    }
    return args, mesh["skin"][...], [drive[i] for i in first]


def compute(ctx: StageContext) -> None:
    """displacements (T,n,3) float32 m, skin displacements, energies (T,) J, von Mises (T,) Pa."""
    import numpy as np

    from physanim.fem.simulate import simulate

    params: SimulateStageParams = ctx.params  # type: ignore[assignment]
    args, skin, driven_names = simulate_inputs(
        ctx.input("align"), ctx.input("tetra"), ctx.input("materials"), params.drive
    )
    result = simulate(**args, params=params, progress=ctx.progress("simulate"))
    ctx.write_record(result)
    ctx.write("skin_nodes", np.nonzero(skin)[0])
    ctx.write("skin_displacements", result.displacements[:, skin])
    ctx.write("driven_nodes", args["driven_idx"])
    ctx.out.attrs["driven_landmarks"] = driven_names
    ctx.summary.update(
        frames=len(result.displacements),
        dt_s=result.dt,
        substeps_per_frame=result.n_substeps,
        max_displacement_mm=round(float(np.abs(result.displacements).max()) * 1e3, 3),
        peak_von_mises_kPa=round(float(result.max_von_mises.max()) / 1e3, 3),
        inverted_tets=int(len(result.inverted_tets)),
        seconds={k: round(v, 3) for k, v in result.timings.items()},
    )


SPEC = StageSpec(
    name="simulate",
    upstream=("align", "tetra", "materials"),
    params=SimulateStageParams,
    version="1",
    compute=compute,
    doc="viscoelastic FEM (Newmark, partitioned prescribed DOFs) driven by tracked landmarks",
)
