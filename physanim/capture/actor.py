"""The demo actor: pymeshlab's real face range scan, cleaned and put into the actor frame.

Actor frame (see ``physanim.face.landmarks``): metres, +x the actor's left, +y up, +z out
of the face, origin at the pronasale of the neutral face.

How the frame is found on the raw scan (automatically, so it is reproducible):
1. forward axis = area-weighted mean normal of the scan, oriented towards the scanner;
2. left-right axis = normal of the face's best bilateral symmetry plane: the scan is
   mirrored and registered back onto itself with point-to-plane ICP (Open3D); the linear
   part of mirror-then-ICP is a reflection whose -1 eigenvector is the plane's normal;
3. up = forward x left; pronasale = the most forward vertex within 1 cm of the plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from physanim.mesh.scan_io import clean_scan, face000_path, load_scan


@dataclass(frozen=True)
class Actor:
    """Neutral actor mesh: ``vertices`` (N, 3) m in the actor frame, ``faces`` (M, 3) int64."""

    vertices: np.ndarray
    faces: np.ndarray


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def symmetry_normal(vertices: np.ndarray, left_hint: np.ndarray, max_dist_m: float) -> np.ndarray:
    """Unit normal (3,) of the best bilateral symmetry plane of a point set (N, 3) m.

    ``left_hint`` (3,) is the approximate left-right direction (also fixes the sign);
    ``max_dist_m`` is the ICP correspondence distance.
    """
    centre = vertices.mean(axis=0)
    vertices = vertices[::4]  # a quarter of the points is plenty for ICP
    h = _unit(left_hint)
    mirror = np.eye(3) - 2.0 * np.outer(h, h)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector((vertices - centre) @ mirror.T))
    dst = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(vertices - centre))
    dst.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=20))
    reg = o3d.pipelines.registration.registration_icp(
        src,
        dst,
        max_dist_m,
        np.eye(4),
        o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=60),
    )
    reflection = reg.transformation[:3, :3] @ mirror
    w, vecs = np.linalg.eig(reflection)
    normal = np.real(vecs[:, np.argmin(np.real(w))])
    # Open3D's ICP sums over threads in no fixed order: the plane differs in the last bits
    # from process to process, and the remeshed scan (scan stage) with it. Rounded to 1e-12
    # (far below any geometric meaning), the actor frame is the same bytes every run.
    normal = np.round(_unit(normal if normal @ h > 0 else -normal), 12)
    return _unit(normal)


def to_actor_frame(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Rigidly move a face scan (N, 3) m, scanner at +z, +y roughly up, into the actor frame."""
    tri = vertices[faces]
    forward = _unit(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).sum(axis=0))
    if forward[2] < 0:
        forward = -forward
    up0 = _unit(np.array([0.0, 1.0, 0.0]) - forward[1] * forward)
    left = symmetry_normal(vertices, np.cross(up0, forward), max_dist_m=0.005)
    forward = _unit(forward - (forward @ left) * left)
    up = np.cross(forward, left)
    rot = np.stack([left, up, forward])  # rows: actor axes in scanner coordinates
    local = (vertices - vertices.mean(axis=0)) @ rot.T
    near_plane = np.abs(local[:, 0]) < 0.01
    tip = np.nonzero(near_plane)[0][np.argmax(local[near_plane, 2])]
    return local - local[tip]


def build_actor(
    *,
    crop_radius_m: float = 0.088,
    crop_center_m: tuple[float, float, float] = (0.0, -0.005, -0.06),
    max_hole_edges: int = 60,
) -> Actor:
    """Load face000 (mm), clean it, move it to the actor frame and crop it to the face.

    The crop keeps faces within ``crop_radius_m`` (m) of ``crop_center_m`` (actor frame,
    m); this drops the headband and ear of the raw scan.
    """
    vertices, faces = load_scan(face000_path(), "mm")
    vertices, faces = clean_scan(vertices, faces, max_hole_edges=max_hole_edges)
    vertices = to_actor_frame(vertices, faces)
    vertices, faces = clean_scan(
        vertices,
        faces,
        max_hole_edges=max_hole_edges,
        crop_radius_m=crop_radius_m,
        crop_center=np.asarray(crop_center_m),
    )
    return Actor(vertices=vertices, faces=faces)
