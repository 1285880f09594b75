"""Where to crop a captured frame so that the face fills a panel tile."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def face_crop(
    uv: NDArray, image_hw: tuple[int, int], tile_wh: tuple[int, int], margin: float = 0.6
) -> tuple[int, int, int, int]:
    """Crop box (row0, row1, col0, col1) px around the tracked landmarks ``uv`` (T, K, 2) px
    (NaN: unseen): their bounding box over all frames grown by ``margin`` (0.6: 60 %), with
    the aspect of a tile (width, height) px, clipped to the image (height, width); the whole
    image when no landmark was seen."""
    h, w = image_hw
    seen = uv[np.isfinite(uv).all(axis=-1)]
    if not len(seen):
        return (0, h, 0, w)
    (u0, v0), (u1, v1) = seen.min(axis=0), seen.max(axis=0)
    half_h = (1 + margin) / 2 * max(v1 - v0, (u1 - u0) * tile_wh[1] / tile_wh[0])
    half_w = half_h * tile_wh[0] / tile_wh[1]
    cu, cv = (u0 + u1) / 2, (v0 + v1) / 2
    return (max(int(cv - half_h), 0), min(int(cv + half_h), h),
            max(int(cu - half_w), 0), min(int(cu + half_w), w))  # fmt: skip
