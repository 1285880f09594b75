"""Parameters of the landmark tracking stage (``track``)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class TrackParams(BaseModel):
    """Marker detection, labelling, Lucas-Kanade tracking, 3D lifting and smoothing."""

    model_config = ConfigDict(extra="forbid")

    backend: Literal["markers", "markerless"] = Field(
        "markers",
        description="landmark source: painted markers, or markerless (MediaPipe face mesh, "
        "needs the markerless extra)",
    )
    marker_rgb: tuple[float, float, float] = Field(
        (0.22, 0.36, 0.42), description="albedo of the painted dots, linear RGB in [0, 1]"
    )
    chroma_tolerance: float = Field(
        0.07, gt=0.0, le=1.0, description="max chromaticity distance of a marker pixel (unitless)"
    )
    min_area_px: int = Field(3, ge=1, description="smallest dot area (pixels)")
    max_area_px: int = Field(400, ge=1, description="largest dot area (pixels)")
    label_gate_px: float = Field(
        12.0, gt=0.0, description="max template-to-dot distance when labelling frame 0 (px)"
    )
    track_gate_px: float = Field(
        4.0, gt=0.0, description="max distance of a dot from its LK prediction (px)"
    )
    lk_window_px: int = Field(15, ge=5, le=101, description="Lucas-Kanade window side (px)")
    lk_levels: int = Field(3, ge=0, le=8, description="Lucas-Kanade pyramid levels (count)")
    depth_window_px: int = Field(
        5, ge=1, le=31, description="side of the window for the robust depth median (px, odd)"
    )
    smoothing: Literal["none", "one_euro", "kalman"] = Field(
        "kalman", description="temporal filter of 3D tracks (kalman = zero-lag RTS smoother)"
    )
    one_euro_min_cutoff: float = Field(
        3.0, gt=0.0, description="One-Euro minimum cutoff frequency (Hz)"
    )
    one_euro_beta: float = Field(
        500.0, ge=0.0, description="One-Euro speed coefficient (s/m): larger = less lag"
    )
    kalman_accel_std: float = Field(
        2.0, gt=0.0, description="Kalman process noise: random acceleration std (m/s^2)"
    )
    kalman_meas_std: float = Field(
        0.0005, gt=0.0, description="Kalman measurement noise std of a 3D marker (m)"
    )
    markerless_min_detection: float = Field(
        0.5, gt=0.0, lt=1.0, description="markerless: min face-detector score (probability)"
    )
    markerless_min_presence: float = Field(
        0.5, gt=0.0, lt=1.0, description="markerless: min face-mesh presence score (probability)"
    )
    markerless_flow: bool = Field(
        True,
        description="markerless: landmarks follow the first frame with a face by dense optical "
        "flow (DIS), the face mesh's own estimate only where the flow fails its check; false: "
        "the face mesh's estimate in every frame",
    )
    markerless_flow_check_px: float = Field(
        2.0, gt=0.0,
        description="markerless: max forward-backward disagreement of a landmark's flow (px)",
    )  # fmt: skip
    stereo_row_band_px: float = Field(
        2.0, gt=0.0, description="stereo: max row difference of a left/right match (px)"
    )
    stereo_max_disparity_px: float = Field(
        400.0, gt=0.0, description="stereo: largest disparity searched (px)"
    )
    stereo_disparity_jump_px: float = Field(
        6.0, gt=0.0, description="stereo: max disparity change of a marker between frames (px)"
    )
