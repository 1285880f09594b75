"""Stage ``keyframe_render``: capsule-figure frames, MP4 and a joint-angle plot."""

from __future__ import annotations

from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field

from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.keyframes import KeyframesOutput, KeyframeStageParams, project_path


class KeyframeRenderParams(BaseModel):
    """What to draw."""

    model_config = ConfigDict(extra="forbid")
    trail_links: list[str] = Field(
        default_factory=list, description="links whose tips leave trails"
    )
    com_trail: bool = Field(True, description="draw the centre of mass trail")
    azimuth_deg: float = Field(60.0, ge=-360, le=360, description="camera azimuth, deg")
    elevation_deg: float = Field(15.0, ge=-90, le=90, description="camera elevation, deg")


@dataclass(frozen=True)
class KeyframeRenderOutput(StageOutput):
    """No arrays: the output is its files (frames, ``animation.mp4``, the joint-angle plot)."""


def compute(
    params: KeyframeRenderParams,
    keyframes: KeyframesOutput,
    ctx: StageContext[KeyframeRenderParams],
) -> KeyframeRenderOutput:
    """Render the upstream animation into this output's files/."""
    from physanim.dynamics import Figure
    from physanim.dynamics.keyframes import KeyframeSpec, environment, root_path
    from physanim.render.figure import render_animation

    anim = keyframes
    up = ctx.upstream_params("keyframes", KeyframeStageParams)
    spec = KeyframeSpec.from_yaml(project_path(up.file))
    fig = Figure.from_yaml(spec.figure)
    missing = [n for n in params.trail_links if n not in fig.joint_names]
    if missing:
        raise ValueError(f"keyframe_render.trail_links: {missing} are not links of {fig.name}")
    guides = None
    if spec.path is not None:  # the path the base follows (its sampled positions)
        path, _ = root_path(spec)
        guides = {"root path": path.positions}
    written = render_animation(
        fig,
        anim.q,
        anim.placement.base_pos,
        spec.fps,
        ctx.files_dir,
        env=environment(spec),
        trail_links=params.trail_links,
        com=anim.placement.com if params.com_trail else None,
        guides=guides,
        simulated=anim.simulated,
        key_times=[k.frame / spec.fps for k in spec.keys],
        title=spec.name,
        azimuth=params.azimuth_deg,
        elevation=params.elevation_deg,
        progress=ctx.progress("render"),
    )
    files = sorted(str(p.relative_to(ctx.files_dir)) for p in written.values())
    return KeyframeRenderOutput(summary={"files": files})


SPEC = StageSpec.typed(
    "keyframe_render",
    compute,
    version="2",
    doc="capsule figure frames + MP4 + joint-angle plot",
)
