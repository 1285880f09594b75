"""Read image-folder recordings: an Open3D RGBD folder and a calibrated stereo pair.

Frames are image files whose stem is the frame number (``000012.png``); a number absent
from both streams is a gap on the frame grid, an image whose partner (depth, right) is
absent is an error. Colour images are 8-bit RGB, RGBA or greyscale (greyscale is repeated
into the three channels; a greyscale frame among colour ones, or the reverse, is refused:
``ColorFormats``).
Every image file's integrity is checked before it is decoded (``physanim.capture.image_file``:
a PNG's checksums and completeness, a JPEG's end marker): a damaged frame is refused, naming
the file.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from physanim.capture.frames import (
    Capture,
    CaptureError,
    StereoRight,
    check_gaps,
    depth_to_metres,
)
from physanim.capture.image_file import image_damage
from physanim.capture.intrinsics import FORMS, frame_rate, parse_intrinsics, positive_number
from physanim.capture.params import IngestParams
from physanim.capture.stereo import StereoCalibration, StereoDepth

#: Fraction of valid stereo disparities at the ends of the searched range above which ingest
#: warns that the depth range cuts the scene.
MAX_AT_LIMITS = 0.05

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


def _decode(path: Path) -> np.ndarray:
    """The pixels of the image file ``path`` as stored (``cv2.IMREAD_UNCHANGED``), after its
    integrity is checked (``physanim.capture.image_file``)."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CaptureError(f"{path}: cannot read the image ({exc.strerror})") from None
    damage = image_damage(path, data)
    if damage is not None:
        raise CaptureError(f"{path}: {damage}; re-copy or re-export this frame")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise CaptureError(f"{path}: unreadable image; re-copy or re-export this frame")
    return img


def color_channels(img: np.ndarray) -> int:
    """Channels of a decoded colour file: 1 (greyscale), 3 (RGB) or 4 (RGBA)."""
    return 1 if img.ndim == 2 else int(img.shape[2])


def read_color(path: Path) -> np.ndarray:
    """8-bit RGB image (H, W, 3) uint8 from a colour (or greyscale) file."""
    return read_color_frame(path)[0]


def read_color_frame(path: Path) -> tuple[np.ndarray, int]:
    """(8-bit RGB image (H, W, 3) uint8, channels of the file: 1 greyscale, 3 RGB, 4 RGBA)
    of a colour (or greyscale) file."""
    img = _decode(path)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.dtype != np.uint8 or not (img.ndim == 2 or img.shape[2] in (3, 4)):
        raise CaptureError(
            f"{path}: unsupported colour pixel format ({img.dtype}, shape {img.shape}); "
            "expected 8-bit RGB, RGBA or greyscale"
        )
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), 1
    code = cv2.COLOR_BGR2RGB if img.shape[2] == 3 else cv2.COLOR_BGRA2RGB
    return cv2.cvtColor(img, code), color_channels(img)


class ColorFormats:
    """Whether the colour frames read so far are greyscale or colour; a frame unlike the
    others is refused, naming it (a frame re-exported or damaged: its colours would be
    silently wrong). RGB and RGBA frames mix (the alpha channel is dropped). While the
    frames are evenly split (frame 0 unlike frame 1) the odd one is not known yet: the next
    frame decides, or ``finish`` names both."""

    def __init__(self) -> None:
        self.seen: list[tuple[Path, bool]] = []

    def add(self, path: Path, channels: int) -> None:
        self.seen.append((path, channels == 1))
        grey = sum(g for _, g in self.seen)
        colour = len(self.seen) - grey
        if grey and colour and grey != colour:
            odd_grey = grey < colour
            odd = next(p for p, g in self.seen if g == odd_grey)
            usual = next(p for p, g in self.seen if g != odd_grey)
            this, others = ("greyscale", "colour") if odd_grey else ("colour", "greyscale")
            raise CaptureError(
                f"{odd}: a {this} image among {others} frames (such as {usual.name}); "
                "re-export this frame like the others"
            )

    def finish(self) -> None:
        grey = [p for p, g in self.seen if g]
        colour = [p for p, g in self.seen if not g]
        if grey and colour:
            raise CaptureError(
                f"{grey[0]}: greyscale but {colour[0]} is colour; the frames must be all "
                "colour or all greyscale"
            )


def read_depth(path: Path) -> np.ndarray:
    """Raw 16-bit depth (H, W) uint16 from a depth PNG (0 = invalid)."""
    img = _decode(path)
    if img.dtype != np.uint16 or img.ndim != 2:
        raise CaptureError(
            f"{path}: unsupported depth pixel format ({img.dtype}, shape {img.shape}); "
            "expected single-channel 16-bit PNG"
        )
    return img


def _same_size(a: np.ndarray, b: np.ndarray, pa: Path, pb: Path, fix: str) -> None:
    if a.shape[:2] != b.shape[:2]:
        raise CaptureError(
            f"{pa} is {a.shape[1]}x{a.shape[0]} but {pb} is {b.shape[1]}x{b.shape[0]}; {fix}"
        )


def read_rgbd_folder(
    root: Path, params: IngestParams, progress: Callable[[int, int], None] | None = None
) -> Capture:
    """Ingest an Open3D RGBD folder: ``color/``, ``depth/`` (uint16 PNG), ``intrinsic.json``."""
    root = Path(root)
    intr_path = root / "intrinsic.json"
    if not intr_path.is_file():
        raise CaptureError(f"{intr_path}: missing colour-camera intrinsics; {FORMS}")
    try:
        intr = json.loads(intr_path.read_text())
    except ValueError as exc:
        raise CaptureError(f"{intr_path}: not valid JSON ({exc}); {FORMS}") from None
    K, size = parse_intrinsics(intr, intr_path)
    scale = 1.0 / positive_number(intr, "depth_scale", params.rgbd_depth_scale, intr_path)
    fps = frame_rate(intr, "fps", params.fallback_fps, intr_path)
    colors, depths = list_frames(root / "color"), list_frames(root / "depth")
    idx = _paired(colors, depths, "depth")
    missing = check_gaps(idx, str(root), params.max_missing_fraction)
    color = np.empty((len(idx), *size, 3), np.uint8)
    raw = np.empty((len(idx), *size), np.uint16)
    formats = ColorFormats()
    for i, n in enumerate(idx.tolist()):
        (c, channels), d = read_color_frame(colors[n]), read_depth(depths[n])
        formats.add(colors[n], channels)
        _same_size(c, d, colors[n], depths[n], "colour and depth must have the same size "
                   "(register depth to colour first)")  # fmt: skip
        if c.shape[:2] != size:
            raise CaptureError(
                f"{colors[n]}: size {c.shape[1]}x{c.shape[0]} but {intr_path} gives width "
                f"{size[1]}, height {size[0]}; give the intrinsics of these images"
            )
        color[i], raw[i] = c, d
        if progress is not None:
            progress(i + 1, len(idx))
    formats.finish()
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
    matcher = StereoDepth(calib, params, root / "calibration.yaml")
    h, w = matcher.size
    color = np.empty((len(idx), h, w, 3), np.uint8)
    right_color = np.empty_like(color)
    depth = np.empty((len(idx), h, w), np.float32)
    limits = np.zeros((len(idx), 2))
    formats = ColorFormats()
    for i, n in enumerate(idx.tolist()):
        (left, lc), (right, rc) = read_color_frame(lefts[n]), read_color_frame(rights[n])
        formats.add(lefts[n], lc)
        formats.add(rights[n], rc)
        _same_size(
            left, right, lefts[n], rights[n], "left and right images must have the same size"
        )
        if i == 0:
            _check_orientation(matcher, *matcher.rectified(left, right), root)
        color[i], right_color[i], depth[i], limits[i] = matcher.compute(left, right, lefts[n])
        if progress is not None:
            progress(i + 1, len(idx))
    formats.finish()
    warnings = []
    near, far = params.stereo_depth_range_m
    for end, frac, limit in (("far", limits[:, 0], far), ("near", limits[:, 1], near)):
        if frac.mean() > MAX_AT_LIMITS:
            warnings.append(
                f"{root}: {frac.mean():.0%} of the valid disparities sit at the {end} end of the "
                f"searched depth range ({limit:g} m): the scene extends beyond it; widen "
                f"ingest.stereo_depth_range_m (now [{near:g}, {far:g}] m)"
            )
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
        warnings=warnings,
        stereo=StereoRight(right_color, matcher.K[0, 0] * matcher.baseline, matcher.doffs),
    )


def _check_orientation(rig: StereoDepth, left: np.ndarray, right: np.ndarray, root: Path) -> None:
    """Refuse a rectified pair (H, W, 3) whose sparse matches fit the searched depth range
    only with the images swapped."""
    n, as_given, swapped = rig.orientation(left, right)
    if n >= 20 and swapped > 0.3 and swapped > 3 * as_given:
        raise CaptureError(
            f"{root}: left and right look swapped ({swapped:.0%} of {n} row-aligned feature "
            f"matches fit the depth range if swapped, {as_given:.0%} as given); swap the folders "
            "left/ and right/ (a near object sits further right in the left image than in the "
            "right one)"
        )
