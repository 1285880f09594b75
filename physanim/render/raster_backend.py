"""Numpy backend of the face renders: the project's z-buffer rasteriser
(``physanim.capture.raster``, compiled) with Lambert + Blinn-Phong headlight shading in numpy;
no OpenGL at all."""

from __future__ import annotations

import numpy as np

from physanim.cameras import Camera, intrinsics, view_matrix
from physanim.capture.raster import rasterize
from physanim.render.colours import BACKGROUND


def render_numpy(
    vertices: np.ndarray,
    normals: np.ndarray,
    faces: np.ndarray,
    rgb: np.ndarray | None,
    site: str,
    camera: Camera,
    view_size: tuple[int, int],
    colour: np.ndarray,
) -> np.ndarray:
    """(H, W, 3) uint8 view of the mesh at ``vertices`` (N, 3) m with unit ``normals`` (N, 3),
    ``faces`` (M, 3); ``rgb`` uint8 colours per ``site`` ('point' (N, 3) or 'cell' (M, 3)),
    or None for the plain ``colour`` (3,) sRGB 0-1; ``view_size`` = (W, H) px."""
    width, height = view_size
    view = view_matrix(camera)
    cam_pts = vertices @ view[:, :3].T + view[:, 3]
    raster = rasterize(cam_pts, faces, intrinsics(camera, view_size), (height, width), near=1e-3)
    mask = raster.mask
    n = raster.interpolate(normals @ view[:, :3].T, faces)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    pts = raster.interpolate(cam_pts, faces)
    to_eye = -pts / np.linalg.norm(pts, axis=1, keepdims=True)
    n *= np.where((n * to_eye).sum(axis=1) < 0, -1.0, 1.0)[:, None]  # two-sided
    key = np.array([-0.35, -0.45, -1.0])
    key /= np.linalg.norm(key)  # upper-left light, camera frame
    diffuse = 0.6 * np.clip((n * to_eye).sum(axis=1), 0, 1) + 0.3 * np.clip(n @ key, 0, 1)
    half = to_eye + key
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    spec = 0.12 * np.clip((n * half).sum(axis=1), 0, 1) ** 20
    if rgb is None:
        albedo = np.broadcast_to(colour, (mask.sum(), 3))
    elif site == "cell":
        albedo = rgb[raster.face[mask]] / 255.0
    else:
        albedo = raster.interpolate(rgb / 255.0, faces)
    shade = albedo * (0.15 + diffuse)[:, None] + spec[:, None]
    image = np.empty((height, width, 3))
    image[:] = BACKGROUND
    image[mask] = np.clip(shade, 0, 1)
    return np.round(255 * image).astype(np.uint8)
