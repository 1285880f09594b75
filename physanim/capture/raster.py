"""Z-buffer rasteriser for pinhole cameras (one sample at each pixel centre).

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
from functools import cached_property

import numpy as np
from numba import njit


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

    @cached_property
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
    (m) are skipped. Both sides of every triangle are visible (no culling); of triangles at
    the same depth in a pixel, the first in ``faces`` is kept.
    """
    height, width = size
    vertices_cam = np.asarray(vertices_cam, dtype=np.float64)
    uv = np.ascontiguousarray(project(vertices_cam, K))
    z = np.ascontiguousarray(vertices_cam[:, 2])
    face_img = np.full(height * width, -1, dtype=np.int64)
    bary_img = np.zeros((height * width, 3))
    depth_img = np.full(height * width, np.inf)
    _zbuffer(uv, z, np.ascontiguousarray(faces, dtype=np.int64), width, height, near,
             face_img, bary_img, depth_img)  # fmt: skip
    depth_img[face_img < 0] = np.nan
    return Raster(
        face=face_img.reshape(height, width),
        bary=bary_img.reshape(height, width, 3),
        depth=depth_img.reshape(height, width),
    )


# A compiled z-buffer loop rather than numpy: enumerating every triangle's candidate pixels
# as arrays and sorting them by pixel and depth took 41 ms per 640 x 480 view of the demo actor
# (87k triangles) and 60 ms at 1280 x 960 (this loop: 3 and 9 ms), the largest cost of the
# demo's generation.
@njit(cache=True, nogil=True)
def _zbuffer(
    uv: np.ndarray, z: np.ndarray, faces: np.ndarray, width: int, height: int, near: float,
    face_img: np.ndarray, bary_img: np.ndarray, depth_img: np.ndarray,
) -> None:  # fmt: skip
    """Scan-convert ``faces`` into the flat images (pixel centres at integer u, v): screen
    barycentrics from edge functions, then perspective-correct ones (1/z is affine)."""
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        if z[i0] <= near or z[i1] <= near or z[i2] <= near:
            continue
        ax, ay, bx, by, cx, cy = uv[i0, 0], uv[i0, 1], uv[i1, 0], uv[i1, 1], uv[i2, 0], uv[i2, 1]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0.0:
            continue
        umin = max(int(np.ceil(min(ax, bx, cx))), 0)
        umax = min(int(np.floor(max(ax, bx, cx))), width - 1)
        vmin = max(int(np.ceil(min(ay, by, cy))), 0)
        vmax = min(int(np.floor(max(ay, by, cy))), height - 1)
        iz0, iz1, iz2 = 1.0 / z[i0], 1.0 / z[i1], 1.0 / z[i2]
        for py in range(vmin, vmax + 1):
            for px in range(umin, umax + 1):
                w0 = ((bx - px) * (cy - py) - (by - py) * (cx - px)) / area
                w1 = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) / area
                w2 = 1.0 - w0 - w1
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                inv_depth = w0 * iz0 + w1 * iz1 + w2 * iz2
                depth = 1.0 / inv_depth
                p = py * width + px
                if depth < depth_img[p]:
                    depth_img[p] = depth
                    face_img[p] = f
                    bary_img[p, 0] = w0 * iz0 / inv_depth
                    bary_img[p, 1] = w1 * iz1 / inv_depth
                    bary_img[p, 2] = w2 * iz2 / inv_depth
