"""Read image-folder recordings: an Open3D RGBD folder and a calibrated stereo pair.

Frames are image files whose stem is the frame number (``000012.png``); a number absent
from both streams is a gap on the frame grid, an image whose partner (depth, right) is
absent is an error.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from physanim.capture.frames import Capture, CaptureError, check_gaps, depth_to_metres
from physanim.capture.params import IngestParams
from physanim.capture.stereo import StereoCalibration, StereoDepth

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def list_frames(folder: Path) -> dict[int, Path]:
    """Frame number -> image path for the images in ``folder`` (stems must be integers)."""
    if not folder.is_dir():
        raise CaptureError(f"{folder}: image folder missing")
    frames: dict[int, Path] = {}
    for f in sorted(folder.iterdir()):
        if f.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        if not f.stem.isdigit():
            raise CaptureError(f"{f}: frame file names must be frame numbers, e.g. 000012.png")
        frames[int(f.stem)] = f
    if not frames:
        raise CaptureError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)})")
    return frames


def _paired(a: dict[int, Path], b: dict[int, Path], what_b: str) -> np.ndarray:
    """Sorted frame numbers; every frame must exist in both streams."""
    for missing, have in ((set(a) - set(b), a), (set(b) - set(a), b)):
        if missing:
            n = min(missing)
            raise CaptureError(
                f"{have[n]}: no matching {what_b} frame {n:06d} (frames {sorted(missing)[:10]} "
                "exist in only one stream); restore the frame or delete it from both"
            )
    return np.array(sorted(a), dtype=np.int64)


def read_color(path: Path) -> np.ndarray:
    """8-bit RGB image (H, W, 3) uint8 from a colour file."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise CaptureError(f"{path}: unreadable image")
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
        raise CaptureError(
            f"{path}: unsupported colour pixel format ({img.dtype}, shape {img.shape}); "
            "expected 8-bit RGB or RGBA"
        )
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB if img.shape[2] == 3 else cv2.COLOR_BGRA2RGB)


def read_depth(path: Path) -> np.ndarray:
    """Raw 16-bit depth (H, W) uint16 from a depth PNG (0 = invalid)."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise CaptureError(f"{path}: unreadable image")
    if img.dtype != np.uint16 or img.ndim != 2:
        raise CaptureError(
            f"{path}: unsupported depth pixel format ({img.dtype}, shape {img.shape}); "
            "expected single-channel 16-bit PNG"
        )
    return img


def _same_size(a: np.ndarray, b: np.ndarray, pa: Path, pb: Path) -> None:
    if a.shape[:2] != b.shape[:2]:
        raise CaptureError(
            f"{pa} is {a.shape[1]}x{a.shape[0]} but {pb} is {b.shape[1]}x{b.shape[0]}; "
            "colour and depth must have the same size (register depth to colour first)"
        )


def read_rgbd_folder(
    root: Path, params: IngestParams, progress: Callable[[int, int], None] | None = None
) -> Capture:
    """Ingest an Open3D RGBD folder: ``color/``, ``depth/`` (uint16 PNG), ``intrinsic.json``."""
    root = Path(root)
    intr_path = root / "intrinsic.json"
    if not intr_path.is_file():
        raise CaptureError(
            f"{intr_path}: missing calibration; write Open3D's PinholeCameraIntrinsic JSON "
            "(width, height, intrinsic_matrix column-major)"
        )
    try:
        intr = json.loads(intr_path.read_text())
        K = np.asarray(intr["intrinsic_matrix"], dtype=np.float64).reshape(3, 3).T
        size = (int(intr["height"]), int(intr["width"]))
    except (ValueError, KeyError, TypeError) as exc:
        raise CaptureError(f"{intr_path}: invalid intrinsics ({exc!r})") from exc
    scale = 1.0 / float(intr.get("depth_scale", params.rgbd_depth_scale))
    fps = float(intr.get("fps", params.fallback_fps))
    colors, depths = list_frames(root / "color"), list_frames(root / "depth")
    idx = _paired(colors, depths, "depth")
    missing = check_gaps(idx, str(root), params.max_missing_fraction)
    color = np.empty((len(idx), *size, 3), np.uint8)
    raw = np.empty((len(idx), *size), np.uint16)
    for i, n in enumerate(idx.tolist()):
        c, d = read_color(colors[n]), read_depth(depths[n])
        _same_size(c, d, colors[n], depths[n])
        if c.shape[:2] != size:
            raise CaptureError(f"{colors[n]}: size {c.shape[1]}x{c.shape[0]} != {intr_path}")
        color[i], raw[i] = c, d
        if progress is not None:
            progress(i + 1, len(idx))
    return Capture(
        color=color,
        depth=depth_to_metres(raw, scale),
        K=K,
        depth_scale=scale,
        timestamps=idx / fps,
        frame_index=idx,
        fps=fps,
        source=f"Open3D RGBD folder {root} ({size[0]}x{size[1]} @ {fps:g} fps)",
        dropped=missing,
    )


def read_stereo_folder(
    root: Path, params: IngestParams, progress: Callable[[int, int], None] | None = None
) -> Capture:
    """Ingest a stereo pair ``left/``, ``right/`` + ``calibration.yaml``; depth by SGBM."""
    root = Path(root)
    calib = StereoCalibration.load(root / "calibration.yaml")
    lefts, rights = list_frames(root / "left"), list_frames(root / "right")
    idx = _paired(lefts, rights, "right")
    missing = check_gaps(idx, str(root), params.max_missing_fraction)
    fps = calib.fps or params.fallback_fps
    matcher = StereoDepth(calib, params)
    h, w = matcher.size
    color = np.empty((len(idx), h, w, 3), np.uint8)
    depth = np.empty((len(idx), h, w), np.float32)
    for i, n in enumerate(idx.tolist()):
        left, right = read_color(lefts[n]), read_color(rights[n])
        _same_size(left, right, lefts[n], rights[n])
        color[i], depth[i] = matcher.compute(left, right, lefts[n])
        if progress is not None:
            progress(i + 1, len(idx))
    return Capture(
        color=color,
        depth=depth,
        K=matcher.K,
        depth_scale=None,
        timestamps=idx / fps,
        frame_index=idx,
        fps=fps,
        source=(
            f"stereo pair {root} (SGBM, baseline {matcher.baseline * 1e3:.1f} mm, "
            f"{'rectified here' if matcher.rectify else 'pre-rectified'}, "
            f"WLS {'on' if params.wls else 'off'})"
        ),
        dropped=missing,
    )
