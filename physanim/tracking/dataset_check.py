"""``physanim check DATASET``: read a dataset's recording and say what it holds, or each
problem with its fix, before anything is computed.

It runs ingest's reader and checks (``read_capture``), then tracks the face in every frame
with the markerless backend (when its extra is installed) and compares the size of the face,
lifted to 3D with the depth and intrinsics, with the face model, as the track stage will: a
wrong depth scale or wrong intrinsics make the face too large or too small. With the markers
backend it also reads the marker template and counts the painted dots in the first frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from physanim.capture.frames import Capture, CaptureError, Problem
from physanim.capture.ingest import find_source, read_capture
from physanim.capture.params import IngestParams
from physanim.capture.validate import central, subject_distance
from physanim.tracking.params import TrackParams


@dataclass
class CheckReport:
    """What ``check_dataset`` found: ``facts`` (label, text) and ``problems``."""

    facts: list[tuple[str, str]] = field(default_factory=list)
    problems: list[Problem] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when no problem is an error."""
        return not any(p.level == "error" for p in self.problems)

    def lines(self) -> list[str]:
        """The report as text lines: facts, then problems (or that there are none)."""
        width = max((len(k) for k, _ in self.facts), default=0)
        out = [f"  {k:<{width}}  {v}" for k, v in self.facts]
        out += [f"{p.level}: {p.message}" for p in self.problems]
        if not self.problems:
            out.append("ok: no problems found")
        return out


def _depth_facts(cap: Capture) -> str:
    valid = cap.depth[np.isfinite(cap.depth)]
    if not len(valid):
        return "no valid depth"
    lo, hi = np.percentile(valid, [5, 95])
    scale = (
        "computed from the stereo pair"
        if cap.depth_scale is None
        else f"scale {1 / cap.depth_scale:g} units/m"
    )
    centre = np.isfinite(central(cap.depth)).mean()
    near = subject_distance(cap.depth)
    return (
        f"{lo:.2f}-{hi:.2f} m (5-95 %), nearest surface at the centre {near:.2f} m; {scale}; "
        f"valid {cap.valid_fraction.mean():.0%} of pixels ({centre:.0%} of the centre)"
    )


def _faces(cap: Capture, track: TrackParams, report: CheckReport) -> None:
    """Track the face without markers: in how many frames it is found, and its size from the
    depth against the face model (what the track stage checks, ``check_tracks``)."""
    from physanim.tracking.assemble import tracks_from_depth
    from physanim.tracking.checks import SCALE_FIX, SCALE_RANGE, face_scale
    from physanim.tracking.markerless import (
        MarkerlessUnavailableError,
        landmark_template,
        track_markerless_2d,
    )

    required = track.backend == "markerless"
    try:
        uv, conf = track_markerless_2d(cap.color, track)
    except MarkerlessUnavailableError as exc:
        report.facts.append(("face", "not checked (markerless extra not installed)"))
        if required:
            report.problems.append(Problem("error", f"track.backend=markerless: {exc}"))
        return
    n = int((conf > 0).any(axis=1).sum())
    template = landmark_template()
    tracks = tracks_from_depth(uv, conf, cap.depth, cap.K, template, cap.fps, track)
    scale = face_scale(tracks, template)
    text = f"found in {n} of {cap.n_frames} frames (MediaPipe face mesh)"
    if np.isfinite(scale):
        text += f"; {scale:.2f} x the size of the face model (from depth and intrinsics)"
    report.facts.append(("face", text))
    lo, hi = SCALE_RANGE["markerless"]
    if n == 0:
        report.problems.append(Problem("error" if required else "warning", (
            f"{cap.origin}: no face found in any of the {cap.n_frames} frames (detector score "
            f"below track.markerless_min_detection={track.markerless_min_detection}); record "
            "the face frontal, lit and unoccluded"
        )))  # fmt: skip
    elif not (tracks.confidence > 0).any():
        report.problems.append(Problem("error", (
            f"{cap.origin}: the face is found in the colour images but has no valid depth "
            "under it; the depth is empty there or not registered to the colour camera"
        )))  # fmt: skip
    elif np.isfinite(scale) and not lo <= scale <= hi:
        report.problems.append(Problem("error", (
            f"{cap.origin}: the face comes out {scale:.2f} x the size of the face model: "
            f"{SCALE_FIX.replace('; run `physanim check DATASET`', '')}"
        )))  # fmt: skip


def _markers(cap: Capture, track: TrackParams, template: Path, report: CheckReport) -> None:
    from physanim.tracking.detect import detect_markers
    from physanim.tracking.template import load_marker_template

    try:
        names, _ = load_marker_template(template)
    except (OSError, ValueError) as exc:
        report.problems.append(Problem("error", str(exc)))
        return
    dots = len(detect_markers(cap.color[0], track))
    report.facts.append(("markers", f"{dots} dots in frame 0; template {template}: {len(names)}"))
    if dots < 3:
        report.problems.append(Problem("error", (
            f"{cap.origin}: frame 0 has {dots} painted marker dot(s); for a recording without "
            "markers set track.backend=markerless, else adjust track.marker_rgb"
        )))  # fmt: skip


def check_dataset(
    dataset_dir: Path,
    ingest: IngestParams,
    track: TrackParams,
    template: Path | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> CheckReport:
    """Read and check the recording of ``dataset_dir`` with the run's ``ingest`` and
    ``track`` settings (``template``: the marker template of the markers backend)."""
    report = CheckReport()
    try:
        kind, path = find_source(Path(dataset_dir), ingest.source)
    except (FileNotFoundError, CaptureError) as exc:
        report.problems.append(Problem("error", str(exc)))
        return report
    report.facts.append(("source", f"{kind} {path}"))
    try:
        cap, problems = read_capture(dataset_dir, ingest, progress)
    except CaptureError as exc:
        report.problems += [Problem("error", line) for line in str(exc).splitlines()]
        return report
    fx, fy, cx, cy = cap.K[0, 0], cap.K[1, 1], cap.K[0, 2], cap.K[1, 2]
    h, w = cap.color.shape[1:3]
    fov = np.degrees(2 * np.arctan(w / (2 * fx)))
    seconds = (cap.frame_index[-1] + 1) / cap.fps
    gaps = f"{len(cap.dropped)} missing" + (
        f", {len(cap.recovered)} recovered from the bag" if cap.recovered else ""
    )
    report.facts[0] = ("source", cap.source)
    report.facts += [
        (
            "frames",
            f"{cap.n_frames} at {cap.fps:g} fps ({seconds:.1f} s; {gaps})",
        ),
        ("resolution", f"{w}x{h} px"),
        ("intrinsics", f"fx {fx:.1f}, fy {fy:.1f}, cx {cx:.1f}, cy {cy:.1f} px ({fov:.0f} deg)"),
        ("depth", _depth_facts(cap)),
    ]
    report.problems += problems
    if np.isfinite(cap.depth).any():
        _faces(cap, track, report)
    if track.backend == "markers" and template is not None:
        _markers(cap, track, template, report)
    return report
