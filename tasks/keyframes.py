"""Stage ``keyframes``: joint animation with partial dynamics and world placement."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from physanim.dynamics.params import KeyframeParams
from physanim.dynamics.placement import Placement
from physanim.pipeline import DatasetParams, StageContext, StageOutput, StageSpec

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


@dataclass(frozen=True)
class KeyframesOutput(StageOutput):
    """The animation of F frames, n joints (``physanim.dynamics.keyframes.KeyframeResult``):
    ``times`` (F,) s, ``q`` (F, n) rad, ``qd`` (F, n) rad/s, ``simulated`` (F, n) bool, the
    world ``placement``; ``joint_names`` (n), ``fps`` frames/s, the ``figure`` file and the
    animation's ``name``."""

    times: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    simulated: np.ndarray
    placement: Placement
    joint_names: list[str]
    fps: float
    figure: str
    name: str


def fingerprint(_dataset: DatasetParams, params: KeyframeStageParams) -> Mapping[str, str]:
    """Content hashes of the keyframe file and of the figure it names."""
    from physanim.dynamics.keyframes import KeyframeSpec

    spec_path = project_path(params.file)
    spec = KeyframeSpec.from_yaml(spec_path)
    return {
        str(p.name): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in (spec_path, Path(spec.figure))
    }


def compute(params: KeyframeStageParams, ctx: StageContext[KeyframeStageParams]) -> KeyframesOutput:
    """Animate; arrays q, qd (F, n) rad, simulated mask, placement (base_pos, com, ...)."""
    from physanim.dynamics import Figure
    from physanim.dynamics.keyframes import KeyframeSpec, run_keyframes

    spec = KeyframeSpec.from_yaml(project_path(params.file))
    fig = Figure.from_yaml(spec.figure)
    result = run_keyframes(fig, spec, params=params.numerics, progress=ctx.progress("keyframes"))
    contact = result.placement.contact
    summary = dict(
        frames=len(result.q),
        min_clearance_mm=round(float(result.placement.distance.min()) * 1e3, 3),
        airborne_frames=[int(i) for i in (~contact).nonzero()[0]],
    )
    if spec.path is not None:
        steps = np.diff(result.placement.base_pos[:, [0, 2]], axis=0)
        summary["path_length_m"] = round(float(np.linalg.norm(steps, axis=1).sum()), 4)
        summary["path_spacing"] = spec.path.spacing
    return KeyframesOutput(
        result.times, result.q, result.qd, result.simulated, result.placement,
        list(fig.joint_names), spec.fps, spec.figure, spec.name, summary=summary,
    )  # fmt: skip


SPEC = StageSpec.typed(
    "keyframes",
    compute,
    version="2",
    doc="keyframe interpolation, passive dynamics in chosen intervals, contact and flight",
    fingerprint=fingerprint,
)
