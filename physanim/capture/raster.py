"""Vectorised z-buffer rasteriser for pinhole cameras (one sample at each pixel centre).

We rasterise ourselves rather than through VTK/OpenGL because the demo needs exact
ground truth: the precise OpenCV pinhole model (fx, fy, cx, cy), float64 metric depth,
and per-pixel triangle ids and perspective-correct barycentrics, so colour, depth and
the stereo pair agree to the bit and the output does not vary between GL drivers.
The face meshes here have sub-pixel triangles, so enumerating each triangle's pixel
bounding box in numpy is cheap (~1-2 candidate pixels per triangle).

Camera convention (OpenCV): +x right, +y down, +z forward; pixel (row i, column j) has
its centre at image coordinates (u=j, v=i).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Raster:
    """Visibility of a mesh in an image of ``(H, W)`` pixels.

    ``face`` (H, W) int64 triangle index, -1 on background; ``bary`` (H, W, 3) float64
    perspective-correct barycentric weights of the triangle's vertices (0 on background);
    ``depth`` (H, W) float64 z in metres along the optical axis, NaN on background.
    """

    face: np.ndarray
    bary: np.ndarray
    depth: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: pixel covered by the mesh."""
        return self.face >= 0

    def interpolate(self, values: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Interpolate per-vertex ``values`` (N, C) at covered pixels -> (P, C), row-major order."""
        m = self.mask
        tri = faces[self.face[m]]
        w = self.bary[m]
        return np.einsum("pk,pkc->pc", w, values[tri])


def project(points_cam: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pinhole projection of (N, 3) camera-frame points (m) -> (N, 2) pixel coordinates (u, v)."""
    z = points_cam[:, 2]
    u = K[0, 0] * points_cam[:, 0] / z + K[0, 1] * points_cam[:, 1] / z + K[0, 2]
    v = K[1, 1] * points_cam[:, 1] / z + K[1, 2]
    return np.stack([u, v], axis=1)


def rasterize(
    vertices_cam: np.ndarray,
    faces: np.ndarray,
    K: np.ndarray,
    size: tuple[int, int],
    near: float = 0.05,
) -> Raster:
    """Rasterise a triangle mesh seen by a pinhole camera.

    ``vertices_cam`` (N, 3) m in the camera frame, ``faces`` (M, 3) int, ``K`` (3, 3)
    intrinsics in pixels, ``size`` = (H, W). Triangles with a vertex closer than ``near``
    (m) are skipped. Both sides of every triangle are visible (no culling).
    """
    height, width = size
    uv = project(vertices_cam, K)
    z = vertices_cam[:, 2]
    ok = (z[faces] > near).all(axis=1)
    fids = np.nonzero(ok)[0]
    tuv = uv[faces[fids]]  # (F, 3, 2)
    umin = np.maximum(np.ceil(tuv[..., 0].min(axis=1)), 0).astype(np.int64)
    umax = np.minimum(np.floor(tuv[..., 0].max(axis=1)), width - 1).astype(np.int64)
    vmin = np.maximum(np.ceil(tuv[..., 1].min(axis=1)), 0).astype(np.int64)
    vmax = np.minimum(np.floor(tuv[..., 1].max(axis=1)), height - 1).astype(np.int64)
    nx = umax - umin + 1
    ny = vmax - vmin + 1
    keep = (nx > 0) & (ny > 0)
    fids, tuv, umin, vmin, nx, ny = (
        fids[keep],
        tuv[keep],
        umin[keep],
        vmin[keep],
        nx[keep],
        ny[keep],
    )

    counts = nx * ny
    cand = np.repeat(np.arange(len(fids)), counts)
    offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    px = umin[cand] + offset % nx[cand]
    py = vmin[cand] + offset // nx[cand]

    # Screen-space barycentrics from edge functions.
    a, b, c = tuv[cand, 0], tuv[cand, 1], tuv[cand, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        w0 = ((b[:, 0] - px) * (c[:, 1] - py) - (b[:, 1] - py) * (c[:, 0] - px)) / area
        w1 = ((c[:, 0] - px) * (a[:, 1] - py) - (c[:, 1] - py) * (a[:, 0] - px)) / area
    w2 = 1.0 - w0 - w1
    inside = (area != 0) & (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
    cand, px, py = cand[inside], px[inside], py[inside]
    sb = np.stack([w0[inside], w1[inside], w2[inside]], axis=1)

    # Perspective-correct interpolation: 1/z is affine in screen space.
    inv_z = 1.0 / z[faces[fids[cand]]]
    inv_depth = (sb * inv_z).sum(axis=1)
    bary = sb * inv_z / inv_depth[:, None]
    depth = 1.0 / inv_depth

    pix = py * width + px
    order = np.lexsort((depth, pix))
    pix_sorted = pix[order]
    first = order[np.r_[True, pix_sorted[1:] != pix_sorted[:-1]]]

    face_img = np.full(height * width, -1, dtype=np.int64)
    bary_img = np.zeros((height * width, 3))
    depth_img = np.full(height * width, np.nan)
    face_img[pix[first]] = fids[cand[first]]
    bary_img[pix[first]] = bary[first]
    depth_img[pix[first]] = depth[first]
    return Raster(
        face=face_img.reshape(height, width),
        bary=bary_img.reshape(height, width, 3),
        depth=depth_img.reshape(height, width),
    )
