"""Stage ``keyframes``: joint animation with partial dynamics and world placement."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, field_validator

from physanim.dynamics.params import KeyframeParams
from physanim.pipeline import DatasetParams, StageContext, StageSpec

ROOT = Path(__file__).resolve().parent.parent


def project_path(path: str) -> Path:
    """``path`` as given if it exists, else relative to the project root."""
    p = Path(path)
    return p if p.exists() or p.is_absolute() else ROOT / p


class KeyframeStageParams(BaseModel):
    """Which keyframe file to animate, and the numerical settings."""

    model_config = ConfigDict(extra="forbid")
    file: str = Field("configs/keyframes/jump.yaml", description="keyframe YAML (see configs/)")
    numerics: KeyframeParams = Field(default_factory=KeyframeParams)

    @field_validator("file")
    @classmethod
    def _exists(cls, v: str) -> str:
        if not project_path(v).is_file():
            raise ValueError(f"keyframe file {v!r} not found (e.g. configs/keyframes/jump.yaml)")
        return v


def fingerprint(_dataset: DatasetParams, params: BaseModel) -> Mapping[str, str]:
    """Content hashes of the keyframe file and of the figure it names."""
    from physanim.dynamics.keyframes import KeyframeSpec

    spec_path = project_path(params.file)  # type: ignore[attr-defined]
    spec = KeyframeSpec.from_yaml(spec_path)
    return {
        str(p.name): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in (spec_path, Path(spec.figure))
    }


def compute(ctx: StageContext) -> None:
    """Animate; arrays q, qd (F, n) rad, simulated mask, placement (base_pos, com, ...)."""
    import numpy as np

    from physanim.dynamics import Figure
    from physanim.dynamics.keyframes import KeyframeSpec, run_keyframes

    params: KeyframeStageParams = ctx.params  # type: ignore[assignment]
    spec = KeyframeSpec.from_yaml(project_path(params.file))
    fig = Figure.from_yaml(spec.figure)
    result = run_keyframes(fig, spec, params=params.numerics, progress=ctx.progress("keyframes"))
    ctx.write_record(result.placement, prefix="placement")
    for name in ("times", "q", "qd", "simulated"):
        ctx.write(name, getattr(result, name))
    ctx.out.attrs.update(
        joint_names=list(fig.joint_names), fps=spec.fps, figure=spec.figure, name=spec.name
    )
    contact = result.placement.contact
    ctx.summary.update(
        frames=len(result.q),
        min_clearance_mm=round(float(result.placement.distance.min()) * 1e3, 3),
        airborne_frames=[int(i) for i in (~contact).nonzero()[0]],
    )
    if spec.path is not None:
        steps = np.diff(result.placement.base_pos[:, [0, 2]], axis=0)
        ctx.summary["path_length_m"] = round(float(np.linalg.norm(steps, axis=1).sum()), 4)
        ctx.summary["path_spacing"] = spec.path.spacing


SPEC = StageSpec(
    name="keyframes",
    upstream=(),
    params=KeyframeStageParams,
    version="2",
    compute=compute,
    doc="keyframe interpolation, passive dynamics in chosen intervals, contact and flight",
    fingerprint=fingerprint,
)
