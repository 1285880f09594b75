"""Parameters of the face-model fit stage (``fit``)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class FitParams(BaseModel):
    """Regularised, bounded, confidence-weighted fit of pose, Shape Units and Action Units."""

    model_config = ConfigDict(extra="forbid")

    neutral_frames: int = Field(
        1, ge=1, description="number of leading neutral frames (count) averaged for the SU fit"
    )
    su_regularisation: float = Field(
        1e-9, ge=0.0, description="ridge weight on Shape Units (m^2 per unit^2)"
    )
    su_bound: float = Field(
        3.0, gt=0.0, description="Shape Units are bounded to +-su_bound (units)"
    )
    au_regularisation: float = Field(
        1e-9, ge=0.0, description="ridge weight on Action Units (m^2 per unit^2)"
    )
    au_temporal: float = Field(
        1e-9, ge=0.0, description="weight on AU change from the previous frame (m^2 per unit^2)"
    )
    au_max: float = Field(
        1.5, gt=0.0, description="Action Units are bounded to [0, au_max] (units)"
    )
    min_confidence: float = Field(
        0.3, ge=0.0, le=1.0, description="landmarks below this confidence (0-1) are ignored"
    )
    iterations: int = Field(
        6, ge=1, le=100, description="pose / unit alternations per frame (count)"
    )
