"""Plausibility checks of an ingested ``Capture``, before anything is computed from it.

- intrinsics (``physanim.capture.intrinsics.check_camera_matrix``);
- depth: some valid depth near the image centre, where the face should be, and the face at
  a plausible distance (``FACE_DISTANCE_M``) for the depth scale;
- physically implausible depth frames (a damaged file: ROS1 bags carry no checksums):
  depth that is mostly discontinuous (random bytes), or a valid-pixel fraction or median
  depth that jumps away from both neighbouring frames and back.
"""

from __future__ import annotations

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


def implausible_depth_frames(capture: Capture) -> dict[int, str]:
    """Frame numbers (``capture.frame_index``) of physically implausible depth -> why."""
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
    return out, bad
