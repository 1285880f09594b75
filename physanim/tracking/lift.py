"""Lift 2D landmarks to 3D camera-frame points: from a depth image or a rectified stereo pair."""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import map_coordinates


def backproject(uv: np.ndarray, z: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) m from pixels ``uv`` (..., 2) and depths ``z`` (...) m."""
    x = (uv[..., 0] - K[0, 2] - K[0, 1] * (uv[..., 1] - K[1, 2]) / K[1, 1]) / K[0, 0]
    y = (uv[..., 1] - K[1, 2]) / K[1, 1]
    return np.stack([x * z, y * z, z], axis=-1)


def sample(image: NDArray, uv: NDArray) -> NDArray:
    """Bilinear samples (P,) or (P, C) of ``image`` (H, W) or (H, W, C) at pixels ``uv``
    (P, 2) (x, y); NaN outside the image or where a neighbouring pixel is NaN."""
    coords = [uv[:, 1], uv[:, 0]]
    if image.ndim == 2:
        return map_coordinates(image, coords, order=1, mode="constant", cval=np.nan)
    return np.stack([sample(image[..., c], uv) for c in range(image.shape[2])], axis=1)


def sample_depth(depth: np.ndarray, uv: np.ndarray, window: int) -> np.ndarray:
    """Robust depth (K,) m at pixels ``uv`` (K, 2): median of the valid pixels in a window.

    ``depth`` (H, W) m with 0 or NaN marking invalid pixels; ``window`` px (odd side). The
    result is NaN where ``uv`` is NaN, outside the image or no pixel in the window is valid.
    """
    h, w = depth.shape
    r = window // 2
    out = np.full(len(uv), np.nan)
    ok = np.isfinite(uv).all(axis=1)
    centre = np.rint(np.where(ok[:, None], uv, -1e6)).astype(np.int64)
    ok &= (centre[:, 0] >= 0) & (centre[:, 0] < w) & (centre[:, 1] >= 0) & (centre[:, 1] < h)
    if not ok.any():
        return out
    off = np.arange(-r, r + 1)
    rows = np.clip(centre[ok, 1, None, None] + off[None, :, None], 0, h - 1)
    cols = np.clip(centre[ok, 0, None, None] + off[None, None, :], 0, w - 1)
    patch = depth[rows, cols].reshape(ok.sum(), -1).astype(np.float64)
    patch[~(patch > 0)] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows give NaN
        out[ok] = np.nanmedian(patch, axis=1)
    return out


def lift_depth(uv: np.ndarray, depth: np.ndarray, K: np.ndarray, window: int) -> np.ndarray:
    """3D camera-frame points (K, 3) m of pixels ``uv`` (K, 2) on a depth image (H, W) m."""
    return backproject(uv, sample_depth(depth, uv, window), K)


def triangulate_rectified(
    uv_left: np.ndarray, uv_right: np.ndarray, K: np.ndarray, baseline: float, doffs: float = 0.0
) -> np.ndarray:
    """3D points (K, 3) m in the left camera frame from a rectified pair (K, 2) px each.

    Both cameras share intrinsics ``K`` (3, 3) of the left camera, except the right camera's
    principal point column, ``doffs`` px further right; the right camera sits ``baseline`` m
    along +x. Non-positive disparities (``u_left - u_right + doffs``) give NaN.
    """
    disparity = uv_left[:, 0] - uv_right[:, 0] + doffs
    z = np.where(
        disparity > 0, K[0, 0] * baseline / np.where(disparity > 0, disparity, 1.0), np.nan
    )
    uv = np.column_stack([uv_left[:, 0], 0.5 * (uv_left[:, 1] + uv_right[:, 1])])
    return backproject(uv, z, K)
