"""Detect painted marker dots in a colour image: chromaticity mask, blobs, subpixel centroids."""

from __future__ import annotations

import cv2
import numpy as np

from physanim.tracking.params import TrackParams


def marker_weight(image: np.ndarray, params: TrackParams) -> np.ndarray:
    """Per-pixel marker weight (H, W) float32 in [0, 1] of an (H, W, 3) uint8 RGB image.

    The weight falls linearly with the chromaticity distance |rgb / sum(rgb) - c_marker| and
    is 0 beyond ``params.chroma_tolerance``; chromaticity ignores shading. Computed as
    |rgb - c_marker sum(rgb)| / sum(rgb) with OpenCV channel transforms (fast).
    """
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image: expected an (H, W, 3) RGB array, got shape {image.shape}")
    ref = np.asarray(params.marker_rgb, dtype=np.float32)
    ref = ref / ref.sum()
    rgb = image.astype(np.float32)
    offset = cv2.transform(rgb, np.eye(3, dtype=np.float32) - ref[:, None])
    dist2 = cv2.transform(cv2.multiply(offset, offset), np.ones((1, 3), np.float32))
    total = cv2.transform(rgb, np.ones((1, 3), np.float32)) + 1.0
    ratio = cv2.sqrt(dist2) / (total * params.chroma_tolerance)
    return cv2.max(1.0 - ratio, 0.0)


def detect_markers(
    image: np.ndarray, params: TrackParams, roi: tuple[int, int, int, int] | None = None
) -> np.ndarray:
    """Subpixel centres (N, 2) px (u = column, v = row) of the dots in an RGB uint8 image.

    Blobs are 8-connected components of positive marker weight with an area in
    ``[min_area_px, max_area_px]``; each centre is the weight-weighted centroid. ``roi`` =
    (u0, v0, u1, v1) px restricts the search to that window (clipped to the image).
    """
    h, w_img = image.shape[:2]
    u0, v0, u1, v1 = (0, 0, w_img, h) if roi is None else roi
    u0, v0 = max(int(u0), 0), max(int(v0), 0)
    u1, v1 = min(int(u1), w_img), min(int(v1), h)
    if u1 <= u0 or v1 <= v0:
        return np.zeros((0, 2))
    w = marker_weight(image[v0:v1, u0:u1], params)
    n, labels, stats, _ = cv2.connectedComponentsWithStats((w > 0).astype(np.uint8), 8)
    area = stats[:, cv2.CC_STAT_AREA]
    keep = (area >= params.min_area_px) & (area <= params.max_area_px)
    keep[0] = False
    rows, cols = np.nonzero(labels)
    lab = labels[rows, cols]
    ww = w[rows, cols].astype(np.float64)
    total = np.bincount(lab, ww, minlength=n)
    u = np.bincount(lab, ww * cols, minlength=n)
    v = np.bincount(lab, ww * rows, minlength=n)
    keep &= total > 0
    return np.column_stack([u[keep] / total[keep] + u0, v[keep] / total[keep] + v0])
