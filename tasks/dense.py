"""Stage ``dense``: the captured motion of every scan vertex, from every frame's colour and depth.

By default dense capture (``physanim.tracking.dense``: optical flow + depth, registered to the
neutral frame, gaps filled from the neighbours over the kinematic scan's motion); with
``dense.method: kinematic`` the kinematic scan of stage ``align`` (the scan bound to the fitted
face model), as before dense capture existed. Either way its ``motion`` is what the report
calls the captured scan. Version history: CHANGELOG.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from physanim.pipeline import StageContext, StageOutput, StageSpec
from physanim.tracking.dense_params import DenseParams
from physanim.transforms import rotation_angle_deg
from tasks.align import AlignOutput
from tasks.ingest import IngestOutput
from tasks.track import TrackOutput

if TYPE_CHECKING:
    from physanim.tracking.dense import NeutralError
    from physanim.tracking.register import Registration

#: warn when less of the seen skin than this rests in any frame after the neutral one
RESTING_FRACTION_WARNING = 0.5


@dataclass(frozen=True)
class DenseOutput(StageOutput):
    """The captured scan: T frames of the N scan vertices of stage ``align``.

    ``motion`` (T, N, 3) float32 m, positions in the head (actor) frame (read lazily: a Zarr
    array); ``confidence`` (T, N) float32 in [0, 1], 0 where a vertex was not observed and its
    motion was filled from its neighbours (all 1 for the kinematic method); ``head_pose``
    (T, 4, 4) camera <- actor, m (re-estimated from the dense points); ``flow_error_px`` (T,)
    median forward-backward flow disagreement; ``method`` 'dense' or 'kinematic'.
    """

    motion: np.ndarray = field(metadata={"lazy": True})
    confidence: np.ndarray
    head_pose: np.ndarray
    flow_error_px: np.ndarray
    method: str


def compute(
    params: DenseParams,
    ingest: IngestOutput,
    track: TrackOutput,
    align: AlignOutput,
    ctx: StageContext[DenseParams],
) -> DenseOutput:
    """Dense capture of the aligned scan (or its kinematic motion, ``method: kinematic``)."""
    kinematic = np.asarray(align.kinematic[...], dtype=np.float32)
    T, n = kinematic.shape[:2]
    if params.method == "kinematic":
        return DenseOutput(
            kinematic, np.ones((T, n), np.float32), track.head_pose, np.zeros(T), "kinematic",
            summary={"method": "kinematic"},
        )  # fmt: skip
    from physanim.tracking.dense import dense_track

    vertices = align.scan_vertices
    params = params.for_source(ingest.kind)  # a stereo pair's depth wants a wider window
    prior = kinematic - vertices[None] if params.prior == "kinematic" else None
    dense = dense_track(
        ingest.color, ingest.depth, ingest.K, track.head_pose, vertices, align.scan_faces,
        params, prior, ctx.progress("dense"), ingest.stereo, fps=float(ingest.fps),
    )  # fmt: skip
    observed = dense.confidence.mean(axis=1)
    summary = dict(
        method="dense",
        seen_fraction=round(float(dense.seen.mean()), 4),
        observed_fraction_min=round(float(observed.min()), 4),
        observed_fraction_median=round(float(np.median(observed)), 4),
        flow_error_px_median=round(float(np.nanmedian(dense.flow_error_px)), 3),
        seconds_per_frame=round(dense.seconds_per_frame, 3),
        depth_change_sigma_px=params.depth_change_sigma_px,
        unfolded_vertex_frames=dense.unfolded,
    )
    if dense.pose_correction_deg is not None:
        summary["pose_correction_deg_median"] = round(
            float(np.median(dense.pose_correction_deg)), 4
        )
        summary["pose_correction_deg_max"] = round(float(dense.pose_correction_deg.max()), 4)
    parts = []
    if params.rest_factor > 0:
        parts.append(_neutral_summary(dense.neutral))
    if dense.registration is not None:
        parts.append(_registration_summary(dense.registration, track.head_pose[0]))
    warnings = [w for part in parts for w in part.pop("warnings", [])]
    for part in parts:
        summary.update(part)
    if warnings:
        summary["warnings"] = warnings
    motion = (vertices[None] + dense.displacement).astype(np.float32)
    return DenseOutput(
        motion, dense.confidence, dense.head_pose, dense.flow_error_px, "dense", summary=summary
    )


def _neutral_summary(neutral: NeutralError) -> dict[str, object]:
    """The neutral frame's error taken out of the dense motion (RMS, mm), the share of the
    seen skin that rests in some later frame and, when that is under
    ``RESTING_FRACTION_WARNING``, a warning."""
    out: dict[str, object] = dict(
        neutral_error_rms_mm=round(neutral.rms_m * 1e3, 4),
        resting_fraction=round(neutral.resting_fraction, 4),
    )
    if neutral.resting_fraction < RESTING_FRACTION_WARNING:
        out["warnings"] = [
            f"only {neutral.resting_fraction:.0%} of the skin the neutral frame sees rests in "
            "any later frame: the rest keeps the neutral frame's own depth and flow error in "
            "every frame (0.1 mm or so from a depth camera); record a moment of neutral face "
            "after the first frame, or check that frame 0 shows the neutral face"
        ]
    return out


def _registration_summary(reg: Registration, tracker_pose: np.ndarray) -> dict[str, object]:
    """How far registering the scan to the neutral depth moved the tracker's neutral head pose
    ``tracker_pose`` (4, 4) (mm, degrees), the registration's RMS residual (mm) and, when it
    was not applied, a warning."""
    change = np.linalg.inv(tracker_pose) @ reg.pose
    turn = rotation_angle_deg(change[:3, :3])
    out: dict[str, object] = dict(
        registration_shift_mm=round(float(np.linalg.norm(change[:3, 3])) * 1e3, 3),
        registration_turn_deg=round(float(turn), 3),
        registration_rms_mm=round(reg.rms_m * 1e3, 3),
    )
    if not reg.converged:
        out["warnings"] = [
            f"the scan did not register to the neutral frame's depth ({reg.inliers} of "
            f"{reg.candidates} facing scan points within reach): dense capture kept the "
            "tracker's head pose, which biased landmarks (markerless) put off the face; check "
            "that the scan is the actor's and that frame 0 shows the neutral face"
        ]
    return out


SPEC = StageSpec.typed(
    "dense",
    compute,
    version="11",
    doc="captured motion of every scan vertex: dense capture (flow + depth) or the kinematic scan",
)
