"""Bring the motion mesh (wireframe fit at the neutral frame) into the scan's frame.

Three steps, all on arrays in metres in the project's actor frame (+x actor's left, +y up,
+z out of the face, see :mod:`physanim.face.landmarks`):

1. ``physanim.transforms.fit_transform`` -- least-squares similarity (or rigid) transform
   from landmark pairs (Umeyama 1991).
2. :func:`per_axis_scale` -- the seed's per-axis scaling (SPEC eqs 5.1-5.4): the width ratio
   ``w_s / w_a`` for x and z, and separate height ratios above (``h_s,u / h_a,u``) and below
   (``h_s,d / h_a,d``) the nose tip for y, about the scan's nose tip.
3. :func:`refine_onto_surface` -- a short non-rigid refinement that pulls the wireframe vertices
   onto the scan with a Laplacian-regularised displacement field, landmarks held on their targets.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from physanim.mesh.binding import REGION_FACE, bind_points
from physanim.mesh.params import AlignParams
from physanim.mesh.topology import boundary_vertex_mask, uniform_laplacian
from physanim.transforms import Transform, fit_transform


@dataclass(frozen=True)
class AxisScales:
    """Per-axis scale factors of eqs 5.1-5.4 (dimensionless) and the nose tip they act about."""

    x: float
    z: float
    y_up: float
    y_down: float
    origin: np.ndarray


def measure_axis_scales(
    moving_landmarks: np.ndarray, target_landmarks: np.ndarray, nose_index: int
) -> AxisScales:
    """Width and up/down heights of two corresponding landmark sets (eqs 5.1-5.4).

    Args:
        moving_landmarks: (K, 3) wireframe landmarks, already rigidly aligned, metres.
        target_landmarks: (K, 3) the same landmarks on the scan, metres.
        nose_index: row of the pronasale (nose tip) in both arrays.

    Returns:
        ``x = z = w_s / w_a`` (x-extent ratio), ``y_up = h_s,u / h_a,u`` (extent above the nose
        tip), ``y_down = h_s,d / h_a,d`` (below), origin = the scan's nose tip.
    """

    def measures(x: np.ndarray) -> tuple[float, float, float]:
        y = x[:, 1] - x[nose_index, 1]
        return float(np.ptp(x[:, 0])), float(y.max()), float(-y.min())

    wa, hau, had = measures(np.asarray(moving_landmarks, dtype=np.float64))
    ws, hsu, hsd = measures(np.asarray(target_landmarks, dtype=np.float64))
    for name, v in (("width", wa), ("height above nose tip", hau), ("height below", had)):
        if v <= 0.0:
            raise ValueError(
                f"landmark {name} is zero: per-axis scaling needs landmarks left and right of, "
                "above and below the nose tip (pronasale)"
            )
    return AxisScales(
        x=ws / wa, z=ws / wa, y_up=hsu / hau, y_down=hsd / had, origin=target_landmarks[nose_index]
    )


def per_axis_scale(points: np.ndarray, scales: AxisScales) -> np.ndarray:
    """Apply eqs 5.1-5.4 to (..., 3) points (metres): scale about the nose tip per axis."""
    p = np.asarray(points, dtype=np.float64) - scales.origin
    y_scale = np.where(p[..., 1] > 0.0, scales.y_up, scales.y_down)
    out = np.stack([p[..., 0] * scales.x, p[..., 1] * y_scale, p[..., 2] * scales.z], axis=-1)
    return out + scales.origin


def refine_onto_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    surface_vertices: np.ndarray,
    surface_faces: np.ndarray,
    landmark_vertex_indices: np.ndarray,
    landmark_targets: np.ndarray,
    params: AlignParams,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Pull a wireframe onto a surface with a Laplacian-regularised displacement (non-rigid).

    Each iteration solves, for the displacement u (V, 3) of the wireframe from its input shape,
    ``min sum_i c_i |x_i + u_i - q_i|^2 + lam |L u|^2 + mu sum_l |x_l + u_l - y_l|^2``
    with q_i the closest surface point to the current vertex (c_i = 0 where it is farther than
    ``params.refine_max_distance_m`` or falls off the surface's open border), L the graph
    Laplacian, lam = ``params.refine_smoothness`` and mu = 1e3 holding landmarks on targets.

    Args:
        vertices: (V, 3) wireframe vertices after similarity / per-axis alignment, metres.
        faces: (F, 3) wireframe triangles.
        surface_vertices, surface_faces: the scan, (N, 3) metres and (M, 3).
        landmark_vertex_indices: (K,) wireframe vertex index of each landmark.
        landmark_targets: (K, 3) landmark positions on the scan, metres.
        params: iterations, smoothness and distance cut-off.
        progress: optional callback (done, total) per iteration.

    Returns:
        (V, 3) refined wireframe vertices, metres.
    """
    x0 = np.asarray(vertices, dtype=np.float64)
    n = len(x0)
    lap = uniform_laplacian(faces, n)
    lm = np.asarray(landmark_vertex_indices, dtype=np.int64)
    targets = np.asarray(landmark_targets, dtype=np.float64)
    if targets.shape != (len(lm), 3):
        raise ValueError(f"landmark_targets must have shape ({len(lm)}, 3), got {targets.shape}")
    mu = 1e3
    sel = sp.csr_array((np.ones(len(lm)), (np.arange(len(lm)), lm)), shape=(len(lm), n))
    reg = params.refine_smoothness * (lap.T @ lap) + mu * (sel.T @ sel)
    rhs_lm = mu * sel.T @ (targets - x0[lm])
    border = boundary_vertex_mask(surface_faces, len(surface_vertices))
    x = x0.copy()
    total = params.refine_iterations
    for it in range(total):
        b = bind_points(x, surface_vertices, surface_faces)
        off_border = (b.region != REGION_FACE) & border[surface_faces[b.triangle]].any(axis=1)
        c = ((b.distance <= params.refine_max_distance_m) & ~off_border).astype(np.float64)
        a = (reg + sp.diags_array(c)).tocsc()
        rhs = rhs_lm + c[:, None] * (b.closest - x0)
        u = spla.splu(a).solve(rhs)
        x = x0 + u
        if progress is not None:
            progress(it + 1, total)
    return x


@dataclass(frozen=True)
class Alignment:
    """Result of :func:`align_motion_mesh`.

    Attributes:
        similarity: landmark transform of the wireframe into the scan frame.
        axis_scales: per-axis scaling of eqs 5.1-5.4 (None in 'similarity' mode).
        offset: (V, 3) refinement displacement added after the transforms, metres.
        vertices: (V, 3) the aligned neutral wireframe, metres.
    """

    similarity: Transform
    axis_scales: AxisScales | None
    offset: np.ndarray
    vertices: np.ndarray

    def apply(self, motion: np.ndarray) -> np.ndarray:
        """Bring wireframe positions (..., V, 3) (e.g. the (T, V, 3) motion) into the scan frame.

        The refinement offset is constant over frames, so frame-to-frame displacements are
        those of the transformed motion.
        """
        x = self.similarity.apply(motion)
        if self.axis_scales is not None:
            x = per_axis_scale(x, self.axis_scales)
        return x + self.offset


def align_motion_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    landmark_vertex_indices: np.ndarray,
    scan_vertices: np.ndarray,
    scan_faces: np.ndarray,
    scan_landmarks: np.ndarray,
    nose_index: int,
    params: AlignParams,
    progress: Callable[[int, int], None] | None = None,
) -> Alignment:
    """Align the neutral wireframe (V, 3) to a scan: Umeyama, optional eqs 5.1-5.4, refinement.

    Args:
        vertices: (V, 3) neutral motion-mesh vertices, metres.
        faces: (F, 3) motion-mesh triangles.
        landmark_vertex_indices: (K,) wireframe vertex of each landmark.
        scan_vertices, scan_faces: (N, 3) metres and (M, 3), the prepared scan.
        scan_landmarks: (K, 3) the same landmarks on the scan, metres.
        nose_index: row of the pronasale in the landmark arrays.
        params: scaling mode and refinement settings.
        progress: optional (done, total) callback of the refinement iterations.
    """
    v = np.asarray(vertices, dtype=np.float64)
    lm = np.asarray(landmark_vertex_indices, dtype=np.int64)
    targets = np.asarray(scan_landmarks, dtype=np.float64)
    per_axis = params.scaling == "per_axis"
    sim = fit_transform(v[lm], targets, with_scale=not per_axis)
    x = sim.apply(v)
    scales = None
    if per_axis:
        scales = measure_axis_scales(x[lm], targets, nose_index)
        x = per_axis_scale(x, scales)
    refined = x
    if params.refine_iterations > 0:
        refined = refine_onto_surface(
            x, faces, scan_vertices, scan_faces, lm, targets, params, progress=progress
        )
    return Alignment(similarity=sim, axis_scales=scales, offset=refined - x, vertices=refined)
