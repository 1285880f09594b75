"""Kinematic shape-motion model (seed 004, SPEC eqs 4.15-4.16).

Each bound scan vertex moves by the barycentric blend of its triangle's vertex displacements:
``d = sum_i a_i d_i^tri`` with ``a_i = S_i / S`` the binding weights.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from physanim.mesh.binding import Binding


def blend_matrix(binding: Binding, faces: np.ndarray, n_vertices: int) -> sp.csr_array:
    """Sparse (N, V) matrix W with W @ X = barycentric blend of per-vertex values X (V, ...).

    Args:
        binding: binding of N points to the mesh (``triangle`` (N,), ``weights`` (N, 3)).
        faces: (F, 3) int triangles of the motion mesh.
        n_vertices: V, the number of motion-mesh vertices.
    """
    faces = np.asarray(faces, dtype=np.int64)
    n = len(binding.triangle)
    cols = faces[binding.triangle]  # (N, 3)
    if cols.size and cols.max() >= n_vertices:
        raise ValueError(
            f"faces index vertex {cols.max()} but the motion mesh has {n_vertices} vertices"
        )
    rows = np.repeat(np.arange(n), 3)
    return sp.csr_array((binding.weights.ravel(), (rows, cols.ravel())), shape=(n, n_vertices))


def animate_bound_points(
    rest_points: np.ndarray,
    binding: Binding,
    faces: np.ndarray,
    motion: np.ndarray,
    reference_frame: int = 0,
) -> np.ndarray:
    """Move bound points with the motion mesh (eqs 4.15-4.16), batched over frames.

    Args:
        rest_points: (N, 3) bound points (scan vertices) at the reference frame, metres.
        binding: their binding to the motion mesh at the reference frame.
        faces: (F, 3) int triangles of the motion mesh.
        motion: (T, V, 3) motion-mesh vertex positions per frame, metres.
        reference_frame: frame index at which the binding was made (displacements are relative
            to it).

    Returns:
        (T, N, 3) point positions per frame, metres.
    """
    motion = np.asarray(motion, dtype=np.float64)
    rest_points = np.asarray(rest_points, dtype=np.float64)
    if motion.ndim != 3 or motion.shape[2] != 3:
        raise ValueError(f"motion must have shape (T, V, 3), got {motion.shape}")
    if rest_points.shape != (len(binding.triangle), 3):
        raise ValueError(
            f"rest_points must have shape ({len(binding.triangle)}, 3) to match the binding, "
            f"got {rest_points.shape}"
        )
    n_frames, n_vertices, _ = motion.shape
    if not 0 <= reference_frame < n_frames:
        raise ValueError(f"reference_frame {reference_frame} outside [0, {n_frames})")
    w = blend_matrix(binding, faces, n_vertices)
    return rest_points[None] + blend_frames(w, motion - motion[reference_frame])


def blend_frames(w: sp.csr_array, values: np.ndarray) -> np.ndarray:
    """Apply a blend matrix (N, V) to per-frame values (T, V, 3) -> (T, N, 3), one product."""
    values = np.asarray(values, dtype=np.float64)
    n_t, n_v, _ = values.shape
    blended = w @ values.transpose(1, 0, 2).reshape(n_v, n_t * 3)  # (N, T*3)
    return blended.reshape(-1, n_t, 3).transpose(1, 0, 2)
