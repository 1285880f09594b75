"""The perspective camera of the face renders (and of the evaluation's silhouettes): frontal
framing, turntable, world -> camera frame, pinhole intrinsics.

Frames: actor frame (+x actor's left, +y up, +z out of the face), so the frontal camera sits
on +z and the actor's left appears on the image's right, as in a photograph.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class Camera:
    """Perspective camera: ``position``, ``focal_point`` (3,) m, ``view_up`` (3,) unit,
    ``view_angle`` vertical field of view in degrees (VTK's convention)."""

    position: tuple[float, float, float]
    focal_point: tuple[float, float, float]
    view_up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    view_angle: float = 20.0


def frontal_camera(
    neutral: np.ndarray,
    size: tuple[int, int] = (480, 640),
    *,
    margin: float = 1.08,
    view_angle: float = 20.0,
    bar_px: int = 0,
) -> Camera:
    """Camera on +z looking at the centre of the bounding box of ``neutral`` (N, 3) m, at the
    distance where the box (times ``margin``) just fits the view of ``size`` = (W, H) pixels
    less a strip of ``bar_px`` rows (a colour bar).  Share it over all frames of a sequence."""
    v = np.asarray(neutral, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo) * margin
    width, height = size
    aspect = width / (height - bar_px)
    tan_half = np.tan(np.radians(view_angle) / 2)
    dist = max(half[1], half[0] / aspect) / tan_half + half[2]
    return Camera(
        position=tuple(centre + [0.0, 0.0, dist]),
        focal_point=tuple(centre),
        view_angle=view_angle,
    )


def turntable(camera: Camera, azimuth_deg: float) -> Camera:
    """``camera`` rotated by ``azimuth_deg`` about its view-up axis through the focal point
    (positive: the camera moves towards +x, i.e. shows more of the actor's left)."""
    up = np.asarray(camera.view_up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    focal = np.asarray(camera.focal_point, dtype=np.float64)
    r = np.asarray(camera.position) - focal
    a = np.radians(azimuth_deg)
    # Rodrigues rotation of r about up.
    rot = r * np.cos(a) + np.cross(up, r) * np.sin(a) + up * (up @ r) * (1 - np.cos(a))
    return replace(camera, position=tuple(focal + rot))


def view_matrix(camera: Camera) -> np.ndarray:
    """(3, 4) world -> OpenCV camera frame (+x right, +y down, +z forward) [R | t]."""
    pos = np.asarray(camera.position, dtype=np.float64)
    forward = np.asarray(camera.focal_point) - pos
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.view_up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rot = np.stack([right, down, forward])
    return np.concatenate([rot, -(rot @ pos)[:, None]], axis=1)


def intrinsics(camera: Camera, size: tuple[int, int]) -> np.ndarray:
    """(3, 3) pinhole matrix K, pixels, of ``camera`` for an image of ``size`` = (W, H) pixels
    (square pixels, the principal point at the image centre)."""
    width, height = size
    f = (height / 2) / np.tan(np.radians(camera.view_angle) / 2)
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
