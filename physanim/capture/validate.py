"""Plausibility checks of an ingested ``Capture``, before anything is computed from it.

- intrinsics (``physanim.capture.intrinsics.check_camera_matrix``);
- depth: some valid depth near the image centre, where the face should be, and the face at
  a plausible distance (``FACE_DISTANCE_M``) for the depth scale;
- physically implausible depth frames (a damaged file: ROS1 bags carry no checksums):
  depth that is mostly discontinuous (random bytes), or a valid-pixel fraction or median
  depth that jumps away from both neighbouring frames and back;
- damaged colour (and depth) pixels: a run of pixels, consecutive in the file's raster order,
  that differs from both neighbouring frames while those agree, and holds random bytes
  (neighbours in the run differ wildly) or zeros (a zeroed block; zeroed depth is invalid
  depth, already marked so). A frame image is stored row after row, so damaged bytes land on
  such a run; a face moving or blinking changes a region, smooth from pixel to pixel, not a
  run of noise. Damage smaller than ``MIN_RUN`` pixels cannot be told from the image and
  passes.
"""

from __future__ import annotations

import cv2
import numpy as np

from physanim.capture.frames import Capture, Problem
from physanim.capture.intrinsics import check_camera_matrix
from physanim.capture.params import IngestParams

#: Distance (m) at which a face plausibly is in front of a face-capture camera.
FACE_DISTANCE_M = (0.2, 2.0)
#: Fraction of the central region with valid depth below which ingest warns.
MIN_CENTRAL_VALID = 0.1
#: A frame whose valid neighbouring pixels differ by more than 10 % of their depth in more
#: than this fraction of the pairs is not a depth image of surfaces.
MAX_ROUGH_FRACTION = 0.3
#: Damaged runs: at least this many consecutive pixels (raster order; gaps of up to two
#: pixels bridged) that differ by more than ``RUN_DIFF`` levels (colour, any channel) or
#: ``RUN_DIFF_REL`` (depth, relative) from both neighbouring frames, which agree within a
#: quarter of that; random when neighbouring pixels of the run differ by more than
#: ``RUN_NOISE`` levels (``RUN_NOISE_REL`` of depth) on average, zeroed when (nearly) all
#: pixels are 0.
MIN_RUN, RUN_DIFF, RUN_NOISE = 16, 40, 50
RUN_DIFF_REL, RUN_NOISE_REL = 0.1, 0.2
#: ... and the pixels right above and below the run are outliers in less than this fraction
#: (damage follows the raster; things in the scene extend over several rows).
MAX_RIM_OUTLIERS = 0.3
#: Spike thresholds against both neighbouring frames: valid fraction (absolute), median
#: depth (relative); the neighbours must agree with each other to a fifth of that.
VALID_JUMP, MEDIAN_JUMP = 0.2, 0.25

DEPTH_FIX = {
    "rgbd": "depth_scale wrong? set depth_scale (raw units per metre, e.g. 1000 for mm, 4000 "
    "for 0.25 mm) in {file}, or ingest.rgbd_depth_scale",
    "bag": "the bag's depth unit is wrong or the subject is out of range; re-record with the "
    "face 0.2-2 m from the camera",
    "stereo": "calibration wrong? in {file}: T in metres, K1/K2 in px of these images",
}


#: The file holding the intrinsics of each kind of folder recording
INTRINSICS_FILE = {"rgbd": "intrinsic.json", "stereo": "calibration.yaml"}


def intrinsics_file(capture: Capture) -> str:
    """The file whose intrinsics ``capture.K`` are (for messages): an RGBD folder's
    intrinsic.json, a stereo folder's calibration.yaml, else the recording (a bag)."""
    where = capture.origin or capture.source
    name = INTRINSICS_FILE.get(capture.kind)
    return f"{where}/{name}" if name and capture.origin else where


def central(depth: np.ndarray) -> np.ndarray:
    """The middle half (rows and columns) of depth images (..., H, W)."""
    h, w = depth.shape[-2:]
    return depth[..., h // 4 : h - h // 4, w // 4 : w - w // 4]


def subject_distance(depth: np.ndarray) -> float:
    """Typical distance (m) of the nearest surfaces near the image centre of depth images
    (T, H, W) m, NaN invalid: the median over frames of each frame's 10th percentile of valid
    central depth (the face is the nearest large surface in a face recording); NaN if none."""
    c = central(depth)
    per_frame = [np.percentile(f[np.isfinite(f)], 10) for f in c if np.isfinite(f).any()]
    return float(np.median(per_frame)) if per_frame else float("nan")


def rough_fraction(depth: np.ndarray) -> np.ndarray:
    """Per frame (T,): fraction of horizontally adjacent valid pixel pairs of depth (T, H, W)
    m whose depths differ by more than 10 % (0 where a frame has no such pair)."""
    n = np.zeros(len(depth), dtype=np.int64)
    jumps = np.zeros(len(depth), dtype=np.int64)
    for t, frame in enumerate(depth):  # one frame at a time: temporaries stay in cache
        a, b = frame[:, 1:], frame[:, :-1]
        ok = np.isfinite(a) & np.isfinite(b)
        a, b = a[ok], b[ok]
        n[t] = len(a)
        jumps[t] = np.count_nonzero(np.abs(a - b) > 0.1 * np.minimum(a, b))
    return np.where(n > 0, jumps / np.maximum(n, 1), 0.0)


def _spikes(values: np.ndarray, jump: float, relative: bool) -> np.ndarray:
    """Frames (T,) bool whose value leaves both neighbours (the next two at the ends) by more
    than ``jump`` while those agree with each other within ``jump / 5``."""
    n = len(values)
    out = np.zeros(n, dtype=bool)
    if n < 3:
        return out

    def diff(x: float, y: float) -> float:
        d = abs(x - y)
        return d / max(min(abs(x), abs(y)), 1e-9) if relative else d

    for t in range(n):
        i, j = (t + 1, t + 2) if t == 0 else (t - 2, t - 1) if t == n - 1 else (t - 1, t + 1)
        v, a, b = values[t], values[i], values[j]
        if not np.isfinite([a, b]).all():
            continue
        if not np.isfinite(v):
            continue  # no valid depth at all: the valid-fraction test sees it
        out[t] = diff(v, a) > jump and diff(v, b) > jump and diff(a, b) <= jump / 5
    return out


def _neighbours(t: int, n: int) -> tuple[int, int]:
    """The two frames frame ``t`` of ``n`` (n >= 3) is compared with: the previous and the
    next, or the next (previous) two at the ends."""
    return (t + 1, t + 2) if t == 0 else (t - 2, t - 1) if t == n - 1 else (t - 1, t + 1)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the runs of at least ``MIN_RUN`` True values of a flat bool array,
    gaps of up to two False values bridged."""
    m = mask.copy()
    m[1:] |= mask[:-1]
    m[:-1] |= mask[1:]  # dilated by one: gaps of two close
    closed = m.copy()
    closed[1:] &= m[:-1]
    closed[:-1] &= m[1:]  # eroded back
    edges = np.flatnonzero(np.diff(np.concatenate(([0], closed.view(np.int8), [0]))))
    starts, stops = edges[::2], edges[1::2]
    keep = stops - starts >= MIN_RUN
    return list(zip(starts[keep].tolist(), stops[keep].tolist(), strict=True))


def _raster_shaped(outlier: np.ndarray, start: int, stop: int, width: int) -> bool:
    """Whether the run [start, stop) of a flat outlier mask (H * W) has a damaged block's
    shape: the pixels right above and below it (outside the run) are mostly not outliers,
    where an object that moves or blinks extends over the rows around too."""
    idx = np.arange(start, stop)
    above = idx[(idx - width < start) & (idx - width >= 0)] - width
    below = idx[(idx + width >= stop) & (idx + width < len(outlier))] + width
    rim = np.concatenate((above, below))
    return not len(rim) or outlier[rim].mean() < MAX_RIM_OUTLIERS


def _channel_max(image: np.ndarray) -> np.ndarray:
    """Per pixel (H, W) the largest channel of an image (H, W, C) uint8 (fast: a dilation
    along the interleaved channels, then every C-th byte)."""
    h, w, ch = image.shape
    kernel = np.ones((1, ch), np.uint8)
    return cv2.dilate(image.reshape(h, w * ch), kernel, anchor=(0, 0))[:, ::ch]


def _damaged_run(values: np.ndarray, noise: float) -> str | None:
    """What a run of pixel values (N, C) holds if it looks like damaged bytes, else None."""
    if (values == 0).all(axis=1).mean() >= 0.9:  # the ends may be partly zeroed pixels
        return "zeroed bytes"
    step = np.abs(np.diff(values, axis=0)).max(axis=1)
    if step.mean() > noise:
        return "random values"
    return None


def damaged_color_frames(color: np.ndarray) -> dict[int, str]:
    """Positions t of colour frames (T, H, W, 3) uint8 holding a damaged run -> where."""
    n = len(color)
    out: dict[int, str] = {}
    if n < 3:
        return out
    for t in range(n):
        i, j = _neighbours(t, n)
        a, b, c = color[i], color[j], color[t]
        outlier = (
            (_channel_max(cv2.absdiff(c, a)) > RUN_DIFF)
            & (_channel_max(cv2.absdiff(c, b)) > RUN_DIFF)
            & (_channel_max(cv2.absdiff(a, b)) <= RUN_DIFF // 4)
        ).ravel()
        if np.count_nonzero(outlier) < MIN_RUN:
            continue
        flat = c.reshape(-1, c.shape[-1]).astype(np.int16)
        runs = [(s, e, _damaged_run(flat[s:e], RUN_NOISE)) for s, e in _runs(outlier)]
        found = _blocks(outlier, [r for r in runs if r[2] is not None], c.shape[1])
        if found:
            out[t] = found
    return out


def _blocks(outlier: np.ndarray, runs: list[tuple[int, int, str | None]], width: int) -> str:
    """Where the first damaged block is ('' if none): ``runs`` (start, stop, what) of damaged
    values, merged when less than a row apart (moving parts of the scene, where the
    neighbouring frames disagree, interrupt a damaged block row by row), then checked for a
    block's raster shape."""
    merged: list[list] = []
    for start, stop, what in runs:
        if merged and start - merged[-1][1] < width:
            merged[-1][1] = stop
        else:
            merged.append([start, stop, what])
    for start, stop, what in merged:
        if _raster_shaped(outlier, start, stop, width):
            return (
                f"{stop - start} pixels from row {start // width}, column {start % width} hold "
                f"{what}, unlike the neighbouring frames"
            )
    return ""


def damaged_depth_runs(depth: np.ndarray) -> dict[int, str]:
    """Positions t of depth frames (T, H, W) m, NaN invalid, holding a run of random valid
    depth values that differs from both neighbouring frames -> where."""
    n = len(depth)
    out: dict[int, str] = {}
    if n < 3:
        return out
    for t in range(n):
        i, j = _neighbours(t, n)
        a, b, d = depth[i], depth[j], depth[t]
        with np.errstate(invalid="ignore"):
            changed = (
                (np.abs(d - a) > RUN_DIFF_REL * a)
                & (np.abs(d - b) > RUN_DIFF_REL * b)
                & (np.abs(a - b) <= RUN_DIFF_REL / 4 * np.minimum(a, b))
            )
        appeared = np.isfinite(d) & np.isnan(a) & np.isnan(b)  # valid where both are not
        outlier = (changed | appeared).ravel()
        if np.count_nonzero(outlier) < MIN_RUN:
            continue
        flat = d.ravel()
        runs = []
        for start, stop in _runs(outlier):
            run = flat[start:stop]
            rel = np.abs(np.diff(run)) / np.minimum(run[1:], run[:-1])
            if np.isfinite(rel).all() and rel.mean() > RUN_NOISE_REL:
                runs.append((start, stop, "random depths"))
        found = _blocks(outlier, runs, d.shape[1])
        if found:
            out[t] = found
    return out


def implausible_depth_frames(capture: Capture) -> dict[int, str]:
    """Frame numbers (``capture.frame_index``) of physically implausible depth -> why."""
    runs = damaged_depth_runs(capture.depth)
    rough = rough_fraction(capture.depth)
    valid_spike = _spikes(capture.valid_fraction, VALID_JUMP, relative=False)
    median_spike = _spikes(capture.depth_median, MEDIAN_JUMP, relative=True)
    out = {}
    for t, n in enumerate(capture.frame_index.tolist()):
        why = []
        if rough[t] > MAX_ROUGH_FRACTION:
            why.append(f"{rough[t]:.0%} of neighbouring pixels jump by > 10 %")
        if valid_spike[t]:
            why.append(f"valid pixels {capture.valid_fraction[t]:.0%} (neighbour frames differ)")
        if median_spike[t]:
            why.append(f"median depth {capture.depth_median[t]:.2f} m (neighbour frames differ)")
        if t in runs:
            why.append(runs[t])
        if why:
            out[n] = "; ".join(why)
    return out


def check_capture(capture: Capture, params: IngestParams) -> tuple[list[Problem], dict[int, str]]:
    """Every finding about ``capture`` (intrinsics, depth, damaged frames), one line each, and
    the implausible depth frames (an error unless ``params.implausible_depth`` allows them)."""
    where = capture.origin or capture.source
    h, w = capture.depth.shape[1:]
    out = check_camera_matrix(capture.K, (h, w), intrinsics_file(capture))
    fix = DEPTH_FIX.get(capture.kind, DEPTH_FIX["rgbd"]).format(file=intrinsics_file(capture))
    if not np.isfinite(capture.depth).any():
        out.append(Problem("error", (
            f"{where}: no valid depth in any of the {capture.n_frames} frames (all zero or "
            "invalid); check that the depth images are the recording's depth stream"
        )))  # fmt: skip
        return out, {}
    valid_centre = float(np.isfinite(central(capture.depth)).mean())
    if valid_centre < MIN_CENTRAL_VALID:
        out.append(Problem("warning", (
            f"{where}: only {valid_centre:.1%} of the image centre has valid depth; frame the "
            "face in the middle of the image, in the depth camera's range"
        )))  # fmt: skip
    z = subject_distance(capture.depth)
    if not FACE_DISTANCE_M[0] <= z <= FACE_DISTANCE_M[1]:
        scale = "" if capture.depth_scale is None else (
            f" with depth_scale {1 / capture.depth_scale:g} units/m"
        )  # fmt: skip
        out.append(Problem("error", (
            f"{where}: the nearest surface at the image centre is {z:.2f} m away{scale}, not a "
            f"face's {FACE_DISTANCE_M[0]:g}-{FACE_DISTANCE_M[1]:g} m: {fix}"
        )))  # fmt: skip
    bad = implausible_depth_frames(capture)
    if bad:
        shown = "; ".join(f"frame {n}: {why}" for n, why in list(bad.items())[:3])
        more = f" (and {len(bad) - 3} more)" if len(bad) > 3 else ""
        action = {
            "error": "re-copy the recording, or set ingest.implausible_depth=drop (their "
            "depth becomes invalid) or =keep",
            "drop": "their depth was made invalid (ingest.implausible_depth=drop)",
            "keep": "kept as they are (ingest.implausible_depth=keep)",
        }[params.implausible_depth]
        level = "error" if params.implausible_depth == "error" else "warning"
        out.append(Problem(level, (
            f"{where}: {len(bad)} physically implausible depth frame(s), the file is probably "
            f"damaged: {shown}{more}; {action}"
        )))  # fmt: skip
    damaged = damaged_color_frames(capture.color)
    if damaged:
        names = capture.frame_index.tolist()
        shown = "; ".join(f"frame {names[t]}: {why}" for t, why in list(damaged.items())[:3])
        more = f" (and {len(damaged) - 3} more)" if len(damaged) > 3 else ""
        keep = params.implausible_depth != "error"
        out.append(Problem("warning" if keep else "error", (
            f"{where}: {len(damaged)} damaged colour frame(s), the file is probably damaged: "
            f"{shown}{more}; "
            + ("kept as read (ingest.implausible_depth=" + params.implausible_depth + ")"
               if keep else "re-copy the recording, or set ingest.implausible_depth=keep")
        )))  # fmt: skip
    return out, bad
