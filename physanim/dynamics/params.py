"""User-tunable parameters of the keyframe stage (composed into the config by the lead)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class KeyframeParams(BaseModel):
    """Numerical settings for keyframe animation with partial dynamics."""

    model_config = ConfigDict(extra="forbid")

    substeps: int = Field(
        default=10, ge=1, le=1000, description="Dynamics steps per frame in simulated intervals."
    )
    method: Literal["crba", "rnea"] = Field(
        default="crba",
        description="Inertia matrix: composite rigid bodies, or the seed's columns by "
        "inverse dynamics (identical results).",
    )
    contact_tolerance: float = Field(
        default=1e-4, gt=0.0, le=0.01, description="Gap counted as touching, m."
    )
    backoff_iterations: int = Field(
        default=40, ge=5, le=100, description="Bisection steps when backing off to first contact."
    )
