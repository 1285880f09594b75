"""Virtual RealSense-like camera rig of the demo: a colour camera (with registered depth)
and a rectified stereo pair whose left camera is the colour camera.

Camera frames follow OpenCV (+x right, +y down, +z forward). Poses are 4x4 rigid
transforms ``world <- camera``; the world frame is the actor frame of the neutral head.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraRig:
    """``K`` (3, 3) px intrinsics shared by all cameras, ``size`` (H, W) px, ``pose_left``
    (4, 4) world <- left/colour camera, ``baseline`` m (right camera at +x of the left)."""

    K: np.ndarray
    size: tuple[int, int]
    pose_left: np.ndarray
    baseline: float

    @property
    def pose_right(self) -> np.ndarray:
        """(4, 4) world <- right camera."""
        shift = np.eye(4)
        shift[0, 3] = self.baseline
        return self.pose_left @ shift


def to_camera(points_world: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """World points (..., 3) m -> camera-frame points for ``pose`` (4, 4) world <- camera."""
    rot, t = pose[:3, :3], pose[:3, 3]
    return (points_world - t) @ rot


def realsense_like_rig(
    *,
    distance_m: float = 0.48,
    height_m: float = 0.015,
    baseline_m: float = 0.06,
    size: tuple[int, int] = (480, 640),
) -> CameraRig:
    """D435-like colour intrinsics at 640x480 (fx 615.1, fy 615.4 px), camera on the actor's
    +z axis at ``distance_m`` from the pronasale plane and ``height_m`` above it, looking
    along -z with image up = actor +y."""
    h, w = size
    sx, sy = w / 640.0, h / 480.0
    K = np.array([[615.1 * sx, 0.0, 322.3 * sx], [0.0, 615.4 * sy, 241.6 * sy], [0.0, 0.0, 1.0]])
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])  # columns: camera axes in the actor frame
    pose[:3, 3] = [0.0, height_m, distance_m]
    return CameraRig(K=K, size=size, pose_left=pose, baseline=baseline_m)
