"""User-tunable parameters of the capture stages (demo generation and ingest)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator


class DemoParams(BaseModel):
    """Parameters of the synthetic demo dataset (``physanim.capture.demo``)."""

    model_config = ConfigDict(extra="forbid")

    seed: int = Field(0, ge=0, description="Random seed (texture, head motion, noise); unitless")
    n_frames: int = Field(90, ge=2, le=10_000, description="Number of frames; count")
    fps: float = Field(30.0, gt=0, le=240, description="Frame rate; frames per second")
    camera_distance_m: float = Field(
        0.48, gt=0.2, le=2.0, description="Camera distance in front of the nose tip; m"
    )
    stereo_baseline_m: float = Field(0.06, gt=0.0, le=0.5, description="Stereo baseline; m")
    depth_noise_m: float = Field(
        0.001, ge=0.0, le=0.05, description="Depth noise std at 0.5 m (grows with z^2); m"
    )
    depth_unit_m: float = Field(0.001, gt=0, le=0.01, description="Depth unit of uint16 depth; m")
    min_cos_view: float = Field(
        0.25, ge=0.0, lt=1.0, description="Depth invalid below this |cos| of the view angle; 1"
    )
    color_noise: float = Field(1.5, ge=0.0, le=20.0, description="Colour noise std; 8-bit levels")
    marker_radius_m: float = Field(0.0016, gt=0, le=0.01, description="Painted dot radius; m")
    supersample: int = Field(2, ge=1, le=4, description="Colour supersampling per axis; count")
    performance: str = Field(
        "demo",
        description="Which performance of physanim.capture.library the actor performs "
        "('demo': jaw drop, then an asymmetric smile)",
    )
    markers: bool = Field(True, description="Paint the marker dots on the skin; bool")

    @field_validator("performance")
    @classmethod
    def _known_performance(cls, v: str) -> str:
        from physanim.capture.library import check_performance  # imports this module

        return check_performance(v)


class IngestParams(BaseModel):
    """Parameters of capture ingest (``physanim.capture.ingest.load_capture``)."""

    model_config = ConfigDict(extra="forbid")

    source: Literal["auto", "bag", "rgbd", "stereo"] = Field(
        "auto", description="Which recording to read; 'auto' detects it from the files"
    )
    max_missing_fraction: float = Field(
        0.2, ge=0.0, le=1.0, description="Refuse input missing more than this fraction of frames; 1"
    )
    fill_dropped_bag_frames: bool = Field(
        True,
        description="Recover frames that Open3D's real-time bag playback dropped by reading "
        "them from the bag directly (they are still reported); bool",
    )
    implausible_depth: Literal["error", "drop", "keep"] = Field(
        "error",
        description="Depth frames that cannot be a depth image of surfaces (damaged file): "
        "refuse the recording, make their depth invalid, or keep them",
    )
    rgbd_depth_scale: float = Field(
        1000.0, gt=0, description="RGBD folders without depth_scale in intrinsic.json: units per m"
    )
    fallback_fps: float = Field(
        30.0, gt=0, description="Frame rate of folders whose metadata has no fps; frames/s"
    )
    stereo_depth_range_m: tuple[float, float] = Field(
        (0.3, 1.2),
        description="Stereo: nearest and farthest depth searched (sets SGBM's disparity range "
        "from the calibration's f_x and baseline); m",
    )

    @field_validator("stereo_depth_range_m")
    @classmethod
    def _depth_range(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 0.0 < v[0] < v[1]:
            raise ValueError(f"{list(v)}: needs 0 < near < far (metres)")
        return v

    block_size: int = Field(5, ge=1, le=21, description="Stereo: SGBM block size (odd); px")

    @field_validator("block_size")
    @classmethod
    def _odd_block(cls, v: int) -> int:
        if v % 2 == 0:
            raise ValueError(f"block_size={v}: SGBM needs an odd block size")
        return v

    uniqueness_ratio: int = Field(10, ge=0, le=100, description="Stereo: SGBM uniqueness; %")
    speckle_window_size: int = Field(
        100, ge=0, le=1000, description="Stereo: speckle filter window (0 = off); px"
    )
    speckle_range: int = Field(2, ge=0, le=64, description="Stereo: speckle disparity range; px")
    lr_max_diff: float = Field(
        1.0, ge=0.0, le=10.0, description="Stereo: left-right consistency tolerance; px"
    )
    min_texture: float = Field(
        1.3,
        ge=0.0,
        le=100.0,
        description="Stereo: invalid where the block's grey-level std is lower; 8-bit levels",
    )
    subpixel_sigma_px: float = Field(
        2.5,
        ge=0.0,
        le=20.0,
        description="Stereo: Gaussian window of the sub-pixel (Lucas-Kanade) refinement of "
        "SGBM's disparity, which removes its pull towards whole pixels (0 = off); px",
    )
    subpixel_iterations: int = Field(
        2, ge=0, le=20, description="Stereo: steps of the sub-pixel refinement; count"
    )
    wls: bool = Field(False, description="Stereo: WLS-filter the disparity (ximgproc); bool")
    wls_lambda: float = Field(8000.0, gt=0, description="Stereo: WLS smoothness lambda; 1")
    wls_sigma: float = Field(1.2, gt=0, description="Stereo: WLS colour sigma; 8-bit levels")
