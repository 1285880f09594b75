"""Stage ``arm_render``: frames and MP4 of the arm per condition, plus comparison plots."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from physanim.muscle.params import ArmConditions
from physanim.pipeline import StageContext, StageSpec
from physanim.store import read_dataclass


class ArmRenderParams(BaseModel):
    """Video settings of the arm renders."""

    model_config = ConfigDict(extra="forbid")
    fps: float = Field(25.0, gt=0, le=240, description="video frame rate, frames/s")
    size_px: int = Field(480, ge=64, le=4096, description="frame width and height, px")


def compute(ctx: StageContext) -> None:
    """Render every condition of the upstream ``muscles`` output into this output's files/."""
    from physanim.muscle.arm import ArmResult
    from physanim.render.arm import (
        plot_condition_summary,
        plot_muscle_curves,
        plot_muscle_timeseries,
        render_arm_video,
    )

    params: ArmRenderParams = ctx.params  # type: ignore[assignment]
    conditions: ArmConditions = ArmConditions.model_validate(
        ctx.store.provenance("muscles", ctx.upstream["muscles"])["params"]
    )
    studies = conditions.resolved()
    solved = ctx.input("muscles")
    results = {n: read_dataclass(ArmResult, solved[n]) for n in studies}
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
    ctx.summary["files"] = sorted(str(p.relative_to(out)) for p in out.rglob("*.mp4"))


SPEC = StageSpec(
    name="arm_render",
    upstream=("muscles",),
    params=ArmRenderParams,
    version="2",
    compute=compute,
    doc="arm frames + MP4 per condition, activation / fibre-length plots",
)
