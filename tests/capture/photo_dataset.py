"""An RGB-D dataset made from a real photo: scikit-image's ``astronaut`` (NASA, public domain)
as colour, moving a few pixels per frame, over synthetic depth (a head-sized ellipsoid in
front of a wall), written in the dataset-root layout (``color/``, ``depth/``,
``intrinsic.json``)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

#: Face centre (u, v) px of the astronaut photo and a focal length that gives her face an
#: adult's size at ``distance_m``.
FACE_UV = (226.0, 130.0)
FX = 500.0


def photo_depth(size: tuple[int, int], shift: tuple[int, int], distance_m: float) -> np.ndarray:
    """Depth (H, W) m: an ellipsoid (half-axes 8 x 11 x 8 cm) whose front is ``distance_m``
    away, centred on the face moved by ``shift`` (rows, cols) px; a wall 0.5 m behind it."""
    h, w = size
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    x = (u - FACE_UV[0] - shift[1]) / FX * distance_m
    y = (v - FACE_UV[1] - shift[0]) / FX * distance_m
    inside = 1.0 - (x / 0.08) ** 2 - (y / 0.11) ** 2
    return np.where(
        inside > 0, distance_m + 0.08 * (1 - np.sqrt(np.clip(inside, 0, 1))), distance_m + 0.5
    )


def write_photo_dataset(
    root: Path,
    photo: np.ndarray,
    *,
    n_frames: int = 4,
    distance_m: float = 0.6,
    depth_unit_m: float = 0.001,
    intrinsics: dict | None = None,
    depth_scale_in_json: bool = True,
) -> Path:
    """Write ``n_frames`` of ``photo`` (H, W, 3) uint8 RGB shifted by 2 px down and 4 px right
    per frame, with uint16 depth in ``depth_unit_m`` units; ``intrinsics`` replaces the
    intrinsic-matrix entries of ``intrinsic.json`` (default: Open3D's column-major list)."""
    h, w = photo.shape[:2]
    (root / "color").mkdir(parents=True, exist_ok=True)
    (root / "depth").mkdir(exist_ok=True)
    for t in range(n_frames):
        shift = (2 * t, 4 * t)
        color = np.roll(photo, shift, axis=(0, 1))
        depth = photo_depth((h, w), shift, distance_m)
        raw = np.clip(np.rint(depth / depth_unit_m), 0, 65535).astype(np.uint16)
        assert cv2.imwrite(str(root / "color" / f"{t:06d}.png"), color[..., ::-1])
        assert cv2.imwrite(str(root / "depth" / f"{t:06d}.png"), raw)
    cx, cy = w / 2, h / 2
    meta: dict = {"width": w, "height": h, "fps": 30.0}
    meta.update(
        intrinsics
        if intrinsics is not None
        else {"intrinsic_matrix": [FX, 0.0, 0.0, 0.0, FX, 0.0, cx, cy, 1.0]}
    )
    if depth_scale_in_json:
        meta["depth_scale"] = 1.0 / depth_unit_m
    (root / "intrinsic.json").write_text(json.dumps(meta))
    return root
