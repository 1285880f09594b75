"""Shared types of capture ingest: the ``Capture`` result, errors, frame-grid bookkeeping."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np


class CaptureError(ValueError):
    """A recording cannot be ingested; the message names the file and the problem."""


class CaptureWarning(UserWarning):
    """A recording was ingested but looks doubtful; the message names the file and the fix."""


@dataclass(frozen=True)
class Problem:
    """One finding about a recording: an ``error`` (refused) or a ``warning``; ``message``
    is one line naming the file, the field or option, and the fix."""

    level: Literal["error", "warning"]
    message: str


@dataclass(frozen=True)
class StereoRight:
    """The right image of a rectified stereo pair beside ``Capture.color`` (the left):
    ``color`` (T, H, W, 3) uint8 RGB, row-aligned with the left image; a point at depth z m
    seen at column x of the left image sits at column ``x - (fx_baseline / z - doffs)`` of the
    right one (``fx_baseline`` = f_x * B, px m; ``doffs`` px, the principal points' offset)."""

    color: np.ndarray = field(metadata={"lazy": True})
    fx_baseline: float
    doffs: float


@dataclass
class Capture:
    """An ingested RGB-D recording.

    ``color`` (T, H, W, 3) uint8 RGB; ``depth`` (T, H, W) float32 m in the colour camera
    (z along the optical axis), NaN where invalid; ``K`` (3, 3) float64 px intrinsics of
    the colour camera; ``depth_scale`` m per raw depth unit (None for stereo depth);
    ``timestamps`` (T,) float64 s from the first frame; ``frame_index`` (T,) int64 index on
    the recording's frame grid (round(t * fps)); ``valid_fraction`` (T,) fraction of valid
    depth pixels; ``depth_median`` (T,) m median valid depth (NaN if none); ``dropped``
    grid indices missing from the output; ``duplicated`` grid indices a reader returned
    more than once (kept once); ``recovered`` indices that the primary reader dropped and
    that were read from the file directly; ``warnings`` one line each (doubtful input);
    ``implausible_depth`` frame numbers whose depth cannot be of surfaces (a damaged file,
    ``physanim.capture.validate``); ``kind`` the source type (bag, rgbd, stereo) and
    ``origin`` the file or folder read; ``stereo`` the right images of a stereo pair (None
    for depth frames).
    """

    color: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    depth_scale: float | None
    timestamps: np.ndarray
    frame_index: np.ndarray
    fps: float
    source: str
    valid_fraction: np.ndarray = field(init=False)
    depth_median: np.ndarray = field(init=False)
    dropped: list[int] = field(default_factory=list)
    duplicated: list[int] = field(default_factory=list)
    recovered: list[int] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    implausible_depth: list[int] = field(default_factory=list)
    kind: str = ""
    origin: str = ""
    stereo: StereoRight | None = None

    def __post_init__(self) -> None:
        self.update_stats()

    def update_stats(self) -> None:
        """Recompute ``valid_fraction`` and ``depth_median`` from ``depth``."""
        valid = np.isfinite(self.depth)
        self.valid_fraction = valid.mean(axis=(1, 2))
        med = np.full(len(self.depth), np.nan)
        for i in np.nonzero(valid.any(axis=(1, 2)))[0]:
            med[i] = np.median(self.depth[i][valid[i]])
        self.depth_median = med

    @property
    def n_frames(self) -> int:
        return len(self.color)


def check_gaps(frame_index: np.ndarray, what: str, max_missing_fraction: float) -> list[int]:
    """Missing grid indices between 0 and the last frame of sorted unique ``frame_index``.

    Raises ``CaptureError`` naming ``what`` if more than ``max_missing_fraction`` of the
    grid is missing.
    """
    if len(frame_index) == 0:
        raise CaptureError(f"{what}: no frames found")
    expected = np.arange(int(frame_index.max()) + 1)
    missing = np.setdiff1d(expected, frame_index).tolist()
    frac = len(missing) / len(expected)
    if frac > max_missing_fraction:
        shown = ", ".join(map(str, missing[:10])) + (" ..." if len(missing) > 10 else "")
        raise CaptureError(
            f"{what}: {len(missing)} of {len(expected)} frames missing ({frac:.0%}; frames "
            f"{shown}), more than max_missing_fraction={max_missing_fraction}; re-export the "
            "recording or raise max_missing_fraction"
        )
    return missing


def depth_to_metres(raw: np.ndarray, scale: float) -> np.ndarray:
    """Raw integer depth (..., H, W), 0 = invalid, times ``scale`` m/unit -> float32 m, NaN."""
    depth = raw.astype(np.float32) * np.float32(scale)
    depth[raw == 0] = np.nan
    return depth
