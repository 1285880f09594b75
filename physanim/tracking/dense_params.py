"""Parameters of dense capture (stage ``dense``, ``physanim.tracking.dense``)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

#: ``depth_change_sigma_px`` (px) where it is not set, by the kind of depth: measured (a bag,
#: an RGBD folder) or from a stereo pair (chosen on the library's tuning performances: the
#: pair's peaks 0.156 -> 0.147 at 6.5 px, its RGB-D peaks best at 4.5).
DEPTH_CHANGE_SIGMA_PX = {"depth": 4.5, "stereo": 6.5}


class DenseParams(BaseModel):
    """Optical flow on colour + depth per frame -> motion of every scan vertex."""

    model_config = ConfigDict(extra="forbid")

    method: Literal["dense", "kinematic"] = Field(
        "dense",
        description="captured motion of the scan: 'dense' (flow + depth of every frame) or "
        "'kinematic' (the scan bound to the fitted face model, stage align)",
    )
    flow_finest_scale: int = Field(
        0, ge=0, le=3, description="DIS flow: finest pyramid level (0 = full resolution); count"
    )
    flow_patch_px: int = Field(
        6, ge=4, le=32,
        description="DIS flow: patch side in the enlarged image's pixels (flow_upsample; "
        "small patches blur less across the lips when the mouth opens); px",
    )  # fmt: skip
    flow_margin_px: int = Field(
        32, ge=0, le=1000,
        description="the flow is computed in the window the scan covers under the tracker's "
        "head poses, widened by this much on each side; px",
    )  # fmt: skip
    flow_stride_px: int = Field(
        3, ge=1, le=16,
        description="DIS flow: patch stride in the enlarged image's pixels (flow_upsample); "
        "at the camera's pixels a stride of 2 lost the lips' rolling; px",
    )  # fmt: skip
    flow_iterations: int = Field(
        16, ge=1, le=200, description="DIS flow: gradient-descent iterations per patch; count"
    )
    flow_refinement_iterations: int = Field(
        5, ge=0, le=50, description="DIS flow: variational refinement iterations; count"
    )
    flow_smoothness: float = Field(
        10.0,
        gt=0.0,
        le=100.0,
        description="DIS flow: smoothness weight of the variational refinement (OpenCV's "
        "alpha; its default 20 blurs the motion across the lip edges); 1",
    )
    flow_constancy_weight: float = Field(
        0.5, ge=0.0, le=100.0,
        description="DIS flow: weight of the variational refinement's brightness-constancy "
        "term (OpenCV's delta; its gradient-constancy term weighs 10); 1",
    )  # fmt: skip
    flow_upsample: int = Field(
        2, ge=1, le=4,
        description="the images are enlarged by this factor (cubic) before the flow, whose "
        "field is then averaged back to the camera's pixels; flow_patch_px and "
        "flow_stride_px count the enlarged pixels; count",
    )  # fmt: skip
    flow_normalise_px: float = Field(
        4.0, ge=0.0, le=50.0,
        description="the flow matches local contrast (the image minus its local mean over its "
        "local standard deviation, Gaussian over this radius) instead of brightness, which "
        "changes as the skin turns under the light (0: brightness); px",
    )  # fmt: skip
    flow_passes: int = Field(
        2, ge=1, le=4,
        description="DIS flow passes: each after the first matches the neutral image against "
        "the frame warped back by the flow so far and adds what is left; one pass reads "
        "8-10 % too little of a lip press's motion on the faint texture of skin; count",
    )  # fmt: skip
    flow_two_way: bool = Field(
        True,
        description="a vertex's pixel at t is the mean of the forward flow's estimate and "
        "the backward flow's (the forward one moved back by half their disagreement); bool",
    )
    depth_sigma_px: float = Field(
        2.5, ge=0.0, le=10.0,
        description="Gaussian smoothing of the neutral frame's depth (the scan's registration "
        "and the seen vertices' neutral positions); px",
    )  # fmt: skip
    depth_change_degree: int = Field(
        2, ge=0, le=2,
        description="the change of depth at a vertex's neutral pixel is read from a polynomial "
        "of this degree fitted to the change around it (Gaussian weights over "
        "depth_change_sigma_px): 0, a weighted mean, flattens a motion's peak (lips pushed "
        "towards the camera) by about sigma^2 / 2 times its curvature, 2 follows it; count",
    )  # fmt: skip
    depth_change_sigma_px: float | None = Field(
        None, gt=0.0, le=20.0,
        description="Gaussian window of the depth change's fit (depth_change_degree); unset: "
        "4.5 from depth frames (a bag, an RGBD folder), 6.5 from a stereo pair, whose depth "
        "is noisier; px",
    )  # fmt: skip
    stereo_flow_weight: float = Field(
        1 / 3, ge=0.0, le=1.0,
        description="from a stereo pair the change of depth is also read from the change of "
        "disparity between the left and the right image's flows, which follow the same skin "
        "in both images; it gets this weight, the matched (SGBM) depth's change the rest "
        "(their errors have other sources; 0: the matched depth only); 1",
    )  # fmt: skip
    stereo_row_tolerance_px: float = Field(
        0.5, gt=0.0, le=10.0,
        description="the right image's flow (stereo_flow_weight) is used only where its "
        "vertical motion agrees with the left image's within this: the rectified pair's "
        "rows are shared, so a disagreement is the flows' own error; px",
    )  # fmt: skip
    visible_tolerance_m: float = Field(
        0.004, gt=0.0, le=0.05,
        description="a vertex is seen in the neutral frame when its depth is this close to "
        "the measured depth; m",
    )  # fmt: skip
    min_cos_view: float = Field(
        0.3, ge=0.0, lt=1.0, description="vertices seen more obliquely are not observed; 1"
    )
    max_flow_error_px: float = Field(
        1.5, gt=0.0, le=20.0,
        description="forward-backward flow disagreement above which a vertex is not "
        "observed in that frame (occluded, inside the open mouth); px",
    )  # fmt: skip
    outlier_m: float = Field(
        0.003, gt=0.0, le=0.05,
        description="observed motion this far from its smoothed neighbourhood is rejected; m",
    )  # fmt: skip
    smoothing_m: float = Field(
        0.0005, ge=0.0, le=0.05,
        description="length over which the motion is smoothed on the scan surface (gaps "
        "are filled from their neighbours over any distance); m",
    )  # fmt: skip
    rest_factor: float = Field(
        5.5, ge=0.0, le=100.0,
        description="a seen vertex rests in a frame where its observed motion, smoothed "
        "over rest_smoothing_m on the scan and a frame in time, is below this times that "
        "smoothed motion's noise per frame (from its second differences over time); the "
        "mean of its observed motion over its rest frames (the neutral frame's own depth "
        "and flow error, which every frame shares) is subtracted from every frame (0: "
        "off); 1",
    )  # fmt: skip
    rest_margin_s: float = Field(
        0.067, ge=0.0, le=1.0,
        description="a frame counts as rest (rest_factor) only where the frames within this "
        "time are too, so a motion's slow start and end are not taken for rest (2 frames at "
        "30 fps); s",
    )  # fmt: skip
    rest_smoothing_m: float = Field(
        0.002, gt=0.0, le=0.05,
        description="length over which the observed motion is smoothed on the scan to tell "
        "rest from motion (rest_factor); m",
    )  # fmt: skip
    pose_rest_factor: float = Field(
        2.0, ge=0.0, le=100.0,
        description="each frame's head pose is corrected by the rigid motion of the seen "
        "vertices that rest there by the rule of rest_factor at this stricter factor, "
        "after the neutral frame's error is taken out (0: off); 1",
    )  # fmt: skip
    fill_iterations: int = Field(
        2, ge=1, le=20,
        description="fill passes: each smooths the kept observations and drops those "
        "farther than outlier_m from the result; count",
    )  # fmt: skip
    prior: Literal["none", "kinematic"] = Field(
        "kinematic",
        description="what unobserved vertices follow: their neighbours' motion only, or the "
        "kinematic scan's motion plus their neighbours' correction",
    )
    temporal_sigma_s: float = Field(
        0.083, ge=0.0, le=1.0,
        description="Gaussian window of the motion's fit over time (temporal_degree; 2.5 "
        "frames at 30 fps; 0: not smoothed over time); s",
    )  # fmt: skip
    temporal_degree: int = Field(
        2, ge=0, le=2,
        description="each vertex's motion over time is smoothed by a polynomial of this "
        "degree fitted around each frame (Gaussian weights over temporal_sigma_s): 0, "
        "a weighted mean, flattens an expression's peak by about sigma^2 / 2 times its "
        "second derivative in time, 2 follows it; count",
    )  # fmt: skip
    register_scan: bool = Field(
        True,
        description="register the scan to the neutral frame's depth (ICP from the landmark "
        "tracker's head pose), so biased landmarks (markerless) do not misplace it; bool",
    )
    register_max_distance_m: float = Field(
        0.02, gt=0.0, le=0.1,
        description="scan registration: farthest scan-to-depth pair kept in the first "
        "iterations (halved down to visible_tolerance_m); m",
    )  # fmt: skip
    refine_head_pose: bool = Field(
        True,
        description="re-estimate the head pose from the dense points that ride rigidly "
        "with the head (the landmark tracker's pose is the start); bool",
    )
    pose_depth_weight: float = Field(
        0.1, gt=0.0, le=1.0,
        description="weight of a point's depth (camera axis) against its image-plane "
        "coordinates in that re-estimated pose: depth is the noisier and, where the skin "
        "bulges towards the camera, the more biased coordinate (1: isotropic); 1",
    )  # fmt: skip
    workers: int = Field(
        0, ge=0, le=64,
        description="threads computing flow: 1 computes each frame's two directions in turn, "
        "2 or more both at once (0: one per core; no more than 2 are used, as each frame's "
        "flow starts from the frame before's); count",
    )  # fmt: skip

    def for_source(self, kind: str) -> DenseParams:
        """These parameters for a recording of ``kind`` ('bag', 'rgbd' or 'stereo'): an unset
        ``depth_change_sigma_px`` takes that kind's default (``DEPTH_CHANGE_SIGMA_PX``)."""
        if self.depth_change_sigma_px is not None:
            return self
        sigma = DEPTH_CHANGE_SIGMA_PX["stereo" if kind == "stereo" else "depth"]
        return self.model_copy(update={"depth_change_sigma_px": sigma})
