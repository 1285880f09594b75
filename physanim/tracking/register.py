"""Rigid registration of a surface to a depth image: projective point-to-plane ICP.

Dense capture poses the scan in the neutral frame by the landmark tracker's head pose; painted
markers give that pose to a fraction of a millimetre, markerless landmarks only to 5-7 mm and
3-4 degrees on the demo actor (the face mesh puts its mouth 5-8 mm too high), which leaves
part of the scan off the measured surface and the rest sliding. Registering the scan to the
neutral depth fixes the pose from the surface itself (on the demo: to 0.1 mm and 0.05 degrees
from starts 10 mm and 10 degrees off), whatever the landmarks' bias.

Each iteration projects the posed points into the depth image (projective association, as in
KinectFusion), takes the measured point and its normal at that pixel, and solves the
linearised point-to-plane problem for a small rotation and translation, Cauchy-weighted;
pairs farther apart than a distance that shrinks from ``max_distance_m`` to
``min_distance_m`` (halving) are dropped, so parts that differ from the scan (hair, a moving
mouth, the background) do not pull the pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from physanim.tracking.lift import backproject, sample


@dataclass(frozen=True)
class Registration:
    """``pose`` (4, 4) camera <- surface frame, m; ``inliers`` points paired at the last
    distance; ``candidates`` points facing the camera inside the image; ``rms_m`` RMS
    point-to-plane residual of the inliers, m."""

    pose: NDArray
    inliers: int
    candidates: int
    rms_m: float

    @property
    def converged(self) -> bool:
        """The surface lies on the depth: at least half its facing points kept."""
        return bool(np.isfinite(self.rms_m)) and self.inliers >= 0.5 * self.candidates


def depth_points(depth: NDArray, K: NDArray) -> tuple[NDArray, NDArray]:
    """Camera-frame points (H, W, 3) m of a depth image (H, W) m (NaN invalid) with
    intrinsics ``K`` (3, 3), and unit normals (H, W, 3) facing the camera (NaN where a
    neighbour is invalid)."""
    h, w = depth.shape
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    points = backproject(np.stack([uu, vv], axis=-1), depth.astype(np.float64), K)
    normals = np.cross(np.gradient(points, axis=1), np.gradient(points, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    normals *= -np.sign(normals[..., 2:3])  # towards the camera (-z)
    return points, normals


def register_to_depth(
    points: NDArray,
    normals: NDArray,
    depth: NDArray,
    K: NDArray,
    pose: NDArray,
    max_distance_m: float,
    min_distance_m: float,
    iterations: int = 8,
) -> Registration:
    """Refine ``pose`` (4, 4) camera <- surface frame so the surface ``points`` (N, 3) m with
    unit ``normals`` (N, 3) lies on ``depth`` (H, W) m (smoothed, NaN invalid; intrinsics
    ``K`` (3, 3)). ``iterations`` per distance level, from ``max_distance_m`` halving down to
    ``min_distance_m`` (m)."""
    measured, measured_normals = depth_points(depth, K)
    pose = np.array(pose, dtype=np.float64)
    distances = [max_distance_m]
    while distances[-1] / 2 >= min_distance_m:
        distances.append(distances[-1] / 2)
    inliers, candidates, rms = 0, 0, float("nan")
    for dmax in distances:
        for _ in range(iterations):
            x = points @ pose[:3, :3].T + pose[:3, 3]
            facing = ((normals @ pose[:3, :3].T) * x).sum(axis=1) < 0
            projected = x @ K.T
            uv = projected[:, :2] / projected[:, 2:]
            target, n = sample(measured, uv), sample(measured_normals, uv)
            residual = ((x - target) * n).sum(axis=1)
            with np.errstate(invalid="ignore"):
                ok = facing & np.isfinite(residual) & (np.linalg.norm(x - target, axis=1) < dmax)
            candidates = int((facing & np.isfinite(uv).all(axis=1)).sum())
            inliers = int(ok.sum())
            if inliers < 6:
                return Registration(pose, inliers, candidates, float("nan"))
            r, n, x = residual[ok], n[ok], x[ok]
            w = 1.0 / (1.0 + (r / (0.5 * dmax)) ** 2)
            A = np.column_stack([np.cross(x, n), n])
            # least squares of minimum norm: motions the surface does not constrain (along a
            # flat patch) stay zero
            step = np.linalg.lstsq(A * np.sqrt(w)[:, None], -r * np.sqrt(w), rcond=1e-9)[0]
            update = np.eye(4)
            update[:3, :3] = Rotation.from_rotvec(step[:3]).as_matrix()
            update[:3, 3] = step[3:]
            pose = update @ pose
            rms = float(np.sqrt(np.mean(r**2)))
    return Registration(pose, inliers, candidates, rms)
