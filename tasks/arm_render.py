"""Stage ``arm_render``: frames and MP4 of the arm per condition, plus comparison plots."""

from __future__ import annotations

from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field

from physanim.muscle.params import ArmConditions
from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.muscles import MusclesOutput


class ArmRenderParams(BaseModel):
    """Video settings of the arm renders."""

    model_config = ConfigDict(extra="forbid")
    fps: float = Field(25.0, gt=0, le=240, description="video frame rate, frames/s")
    size_px: int = Field(480, ge=64, le=4096, description="frame width and height, px")


@dataclass(frozen=True)
class ArmRenderOutput(StageOutput):
    """No arrays: the output is its files (``<condition>/arm.mp4`` and frames, the plots)."""


def compute(
    params: ArmRenderParams, muscles: MusclesOutput, ctx: StageContext[ArmRenderParams]
) -> ArmRenderOutput:
    """Render every condition of the upstream ``muscles`` output into this output's files/."""
    from physanim.render.arm import (
        plot_condition_summary,
        plot_muscle_curves,
        plot_muscle_timeseries,
        render_arm_video,
    )

    conditions = ctx.upstream_params("muscles", ArmConditions)
    studies = conditions.resolved()
    results = {n: muscles.conditions[n] for n in studies}
    out = ctx.files_dir
    base = conditions.base
    for name, study in studies.items():
        render_arm_video(
            results[name],
            study.arm,
            study.shape,
            out / name,
            fps=params.fps,
            size_px=params.size_px,
            title=name,
            progress=ctx.progress(f"render {name}"),
        )
    plot_muscle_timeseries(results, base.arm, out / "activation.png", "activation")
    plot_muscle_timeseries(results, base.arm, out / "fibre_length.png", "fibre_length")
    plot_muscle_curves(out / "muscle_curves.png")
    plot_condition_summary(results, [lk.name for lk in base.arm.links], out / "conditions.png")
    return ArmRenderOutput(
        summary={"files": sorted(str(p.relative_to(out)) for p in out.rglob("*.mp4"))}
    )


SPEC = StageSpec.typed(
    "arm_render",
    compute,
    version="2",
    doc="arm frames + MP4 per condition, activation / fibre-length plots",
    files={
        "activation.png": "Muscle activations per condition",
        "fibre_length.png": "Fibre lengths per condition",
        "muscle_curves.png": "Hill muscle curves",
        "conditions.png": "Conditions compared",
    },
)
