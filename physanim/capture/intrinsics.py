"""Colour-camera intrinsics of an RGBD folder (``intrinsic.json``): parsing and plausibility.

Accepted forms (``width`` and ``height`` in px are always required):

- Open3D's ``PinholeCameraIntrinsic`` JSON: ``intrinsic_matrix`` a flat list of 9 numbers in
  column-major order ``[fx, 0, 0, 0, fy, 0, cx, cy, 1]``;
- ``intrinsic_matrix`` as a list of rows ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``;
- the keys ``fx``, ``fy``, ``cx``, ``cy`` (px; RealSense's ``ppx``, ``ppy`` for ``cx``, ``cy``).

Optional: ``depth_scale`` (raw depth units per metre, e.g. 1000 for millimetres) and ``fps``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from physanim.capture.frames import CaptureError, Problem

FORMS = (
    'write {"width": W, "height": H, "intrinsic_matrix": [fx, 0, 0, 0, fy, 0, cx, cy, 1]} '
    "(Open3D, column-major), or the matrix as rows [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], or "
    'the keys "fx", "fy", "cx", "cy" (px)'
)
#: Horizontal field of view (degrees) a face camera plausibly has.
FOV_RANGE_DEG = (15.0, 150.0)
#: Frame rates (frames/s) a recording's metadata may give.
FPS_RANGE = (1.0, 1000.0)
#: Largest image width or height (px) a recording's metadata may give.
MAX_PIXELS = 100_000


def is_camera_matrix(K: np.ndarray) -> bool:
    """True for a pinhole camera matrix (3, 3): last row [0, 0, 1], K[1, 0] = 0, fx, fy > 0."""
    return bool(np.allclose(K[2], [0.0, 0.0, 1.0]) and K[1, 0] == 0 and K[0, 0] > 0 < K[1, 1])


def _matrix(value: Any, path: Path) -> np.ndarray:
    """(3, 3) K from ``intrinsic_matrix``: flat = Open3D column-major, nested = rows."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CaptureError(f"{path}: intrinsic_matrix: not a list of numbers; {FORMS}") from None
    if arr.shape == (9,):
        K, other, order = arr.reshape(3, 3).T, arr.reshape(3, 3), "row-major"
        fix = "Open3D's flat list is column-major: [fx, 0, 0, 0, fy, 0, cx, cy, 1]"
    elif arr.shape == (3, 3):
        K, other, order = arr, arr.T, "a list of columns"
        fix = "as nested lists write the rows: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
    else:
        raise CaptureError(
            f"{path}: intrinsic_matrix: expected 9 numbers or 3 rows of 3, got shape {arr.shape}; "
            f"{FORMS}"
        )
    if not np.isfinite(K).all():
        raise CaptureError(f"{path}: intrinsic_matrix: contains NaN or infinite values")
    if is_camera_matrix(K):
        return K
    if is_camera_matrix(other):
        raise CaptureError(
            f"{path}: intrinsic_matrix: looks {order} (its last row reads {K[2].tolist()}, "
            f"not [0, 0, 1]); {fix}"
        )
    raise CaptureError(
        f"{path}: intrinsic_matrix: not a camera matrix (last row {K[2].tolist()}, expected "
        f"[0, 0, 1]; fx, fy > 0); {FORMS}"
    )


def _from_keys(data: dict[str, Any], path: Path) -> np.ndarray:
    names = {"fx": ("fx",), "fy": ("fy",), "cx": ("cx", "ppx"), "cy": ("cy", "ppy")}
    vals, missing = {}, []
    for key, aliases in names.items():
        found = [data[a] for a in aliases if a in data]
        if not found:
            missing.append(key)
            continue
        if isinstance(found[0], bool) or not isinstance(found[0], int | float):
            raise CaptureError(f"{path}: {key}: expected a number (px), got {found[0]!r}")
        vals[key] = float(found[0])
    if missing:
        raise CaptureError(f"{path}: no intrinsic_matrix and no {', '.join(missing)}; {FORMS}")
    if vals["fx"] <= 0 or vals["fy"] <= 0:
        raise CaptureError(f"{path}: fx, fy must be positive focal lengths in px")
    return np.array([[vals["fx"], 0.0, vals["cx"]], [0.0, vals["fy"], vals["cy"]], [0, 0, 1.0]])


def positive_number(data: dict[str, Any], key: str, default: float | None, path: Path) -> float:
    """``data[key]`` as a positive, finite float (``default`` when absent; required if None)."""
    value = data.get(key, default)
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not 0 < value < float("inf")
    ):
        raise CaptureError(f"{path}: {key}: expected a positive number, got {value!r}")
    return float(value)


def pixel_count(data: dict[str, Any], key: str, path: Path) -> int:
    """``data[key]`` (required) as an image size in px: a whole number from 1 to
    ``MAX_PIXELS``."""
    value = data.get(key)
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not 1 <= value <= MAX_PIXELS
        or value != int(value)
    ):
        raise CaptureError(
            f"{path}: {key}: expected a whole number of pixels (1-{MAX_PIXELS}), got {value!r}"
        )
    return int(value)


def frame_rate(data: dict[str, Any], key: str, default: float | None, path: Path) -> float:
    """``data[key]`` as a frame rate within ``FPS_RANGE`` (``default``, unchecked, when
    absent)."""
    fps = positive_number(data, key, default, path)
    if key in data and not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
        raise CaptureError(
            f"{path}: {key}: {fps:g} frames/s is not a camera's frame rate "
            f"({FPS_RANGE[0]:g}-{FPS_RANGE[1]:g}); give the recording's frames per second"
        )
    return fps


def parse_intrinsics(data: Any, path: Path) -> tuple[np.ndarray, tuple[int, int]]:
    """(K (3, 3) px, image size (H, W) px) from the parsed ``intrinsic.json`` of ``path``."""
    if not isinstance(data, dict):
        raise CaptureError(f"{path}: expected a JSON object; {FORMS}")
    size = [pixel_count(data, key, path) for key in ("height", "width")]
    K = _matrix(data["intrinsic_matrix"], path) if "intrinsic_matrix" in data else None
    return (K if K is not None else _from_keys(data, path)), (size[0], size[1])


def check_camera_matrix(K: np.ndarray, size: tuple[int, int], where: str) -> list[Problem]:
    """Plausibility of colour intrinsics ``K`` (3, 3) px for images of ``size`` (H, W) px:
    field of view within ``FOV_RANGE_DEG``, principal point inside the image (near its
    centre), square-ish pixels."""
    h, w = size
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    out = []
    fov = float(np.degrees(2 * np.arctan(w / (2 * fx))))
    if not FOV_RANGE_DEG[0] <= fov <= FOV_RANGE_DEG[1]:
        lo = w / (2 * np.tan(np.radians(FOV_RANGE_DEG[1] / 2)))
        hi = w / (2 * np.tan(np.radians(FOV_RANGE_DEG[0] / 2)))
        out.append(Problem("error", (
            f"{where}: fx = {fx:g} px gives a {fov:.0f} deg field of view on {w} px wide "
            f"images (plausible fx {lo:.0f}-{hi:.0f} px); give fx, fy in pixels of these "
            "images (fx = focal length mm x width px / sensor width mm)"
        )))  # fmt: skip
    if not (0 <= cx < w and 0 <= cy < h):
        out.append(Problem("error", (
            f"{where}: principal point ({cx:g}, {cy:g}) px lies outside the {w}x{h} image; "
            "the intrinsics belong to another resolution: scale fx, fy, cx, cy by the size ratio"
        )))  # fmt: skip
    elif abs(cx - w / 2) > 0.25 * w or abs(cy - h / 2) > 0.25 * h:
        out.append(Problem("warning", (
            f"{where}: principal point ({cx:g}, {cy:g}) px is far from the centre of the "
            f"{w}x{h} image; check that the intrinsics are for this resolution and not cropped"
        )))  # fmt: skip
    if not 0.8 <= fx / fy <= 1.25:
        out.append(Problem("warning", (
            f"{where}: fx / fy = {fx / fy:.2f}; cameras have nearly square pixels: check that "
            "fx and fy are not swapped with cx, cy or given for another resolution"
        )))  # fmt: skip
    return out
