"""Closed soft-tissue volume behind the skin: skin in front, bone-side offset behind, rim between.

The bone-side surface is the skin moved inward along smoothed vertex normals by a thickness map
(thinner over the forehead and nose bridge, thicker at the cheeks; :class:`TetraParams`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from physanim.mesh.params import TetraParams
from physanim.mesh.remesh import remesh_isotropic
from physanim.mesh.topology import (
    boundary_edges,
    uniform_laplacian,
    vertex_normals,
    watertight_problems,
)

#: Face part codes of :attr:`TissueSurface.part`.
PART_SKIN, PART_BONE, PART_RIM = 0, 1, 2

#: Feature points the default thickness map needs.
THICKNESS_LANDMARKS = ("glabella", "pronasale", "cheek_L", "cheek_R")


class NotWatertightError(ValueError):
    """A surface that must enclose a volume has holes, non-manifold or mis-oriented edges."""


@dataclass(frozen=True)
class TissueSurface:
    """Closed, outward-oriented triangle surface of the tissue volume.

    Attributes:
        vertices: (2S, 3) metres: skin vertices 0..S-1, then their bone-side copies.
        faces: (F, 3) int64 triangles, normals pointing out of the volume.
        part: (F,) int8 PART_SKIN / PART_BONE / PART_RIM per face.
        thickness: (S,) tissue thickness at each skin vertex, metres.
    """

    vertices: np.ndarray
    faces: np.ndarray
    part: np.ndarray
    thickness: np.ndarray

    @property
    def n_skin(self) -> int:
        """Number S of skin vertices."""
        return len(self.thickness)

    def enclosed_volume(self) -> float:
        """Volume enclosed by the surface (divergence theorem), m^3."""
        t = self.vertices[self.faces]
        return float(np.einsum("fi,fi->", t[:, 0], np.cross(t[:, 1], t[:, 2])) / 6.0)


def _require_landmarks(landmarks: dict[str, np.ndarray], names: tuple[str, ...]) -> None:
    missing = [n for n in names if n not in landmarks]
    if missing:
        raise ValueError(
            f"landmarks lack {missing}; the thickness map needs {list(names)} (actor frame, m)"
        )


def _smoothing_operator(faces: np.ndarray, n_vertices: int) -> sp.csr_array:
    """(V, V) averaging operator: each vertex -> mean of itself and its ring neighbours."""
    lap = uniform_laplacian(faces, n_vertices)
    deg = lap.diagonal()
    adj = sp.diags_array(deg) - lap
    return (sp.diags_array(1.0 / (1.0 + deg)) @ (adj + sp.eye_array(n_vertices))).tocsr()


def thickness_map(
    vertices: np.ndarray, landmarks: dict[str, np.ndarray], params: TetraParams
) -> np.ndarray:
    """Tissue thickness (N,) in metres at skin points (N, 3) in the actor frame (+y up).

    Blends from ``thickness_default_m`` towards: ``thickness_forehead_m`` above the glabella
    (logistic step in y), ``thickness_nose_bridge_m`` near the glabella-pronasale segment and
    ``thickness_cheek_m`` near cheek_L/R (Gaussians of radius ``thickness_falloff_m``).
    """
    _require_landmarks(landmarks, THICKNESS_LANDMARKS)
    v = np.asarray(vertices, dtype=np.float64)
    r = params.thickness_falloff_m
    g = np.asarray(landmarks["glabella"], dtype=np.float64)
    tip = np.asarray(landmarks["pronasale"], dtype=np.float64)
    t = np.full(len(v), params.thickness_default_m)

    w_forehead = 1.0 / (1.0 + np.exp(-np.clip((v[:, 1] - g[1]) / (0.25 * r), -50.0, 50.0)))
    t += w_forehead * (params.thickness_forehead_m - t)

    seg = tip - g
    s = np.clip((v - g) @ seg / max(float(seg @ seg), 1e-12), 0.0, 1.0)
    d_bridge = np.linalg.norm(v - (g + s[:, None] * seg), axis=1)
    w_nose = np.exp(-0.5 * (d_bridge / (0.5 * r)) ** 2)
    t += w_nose * (params.thickness_nose_bridge_m - t)

    d_cheek = np.minimum(
        np.linalg.norm(v - landmarks["cheek_L"], axis=1),
        np.linalg.norm(v - landmarks["cheek_R"], axis=1),
    )
    w_cheek = np.exp(-0.5 * (d_cheek / r) ** 2)
    t += w_cheek * (params.thickness_cheek_m - t)
    return t


def build_tissue_surface(
    skin_vertices: np.ndarray,
    skin_faces: np.ndarray,
    landmarks: dict[str, np.ndarray],
    params: TetraParams,
) -> TissueSurface:
    """Closed tissue surface from the open skin surface (one border loop, normals to +z).

    Args:
        skin_vertices: (N, 3) prepared scan (skin), metres, actor frame.
        skin_faces: (M, 3) int triangles, oriented with normals out of the face.
        landmarks: feature-point name -> (3,) position, metres; needs THICKNESS_LANDMARKS.
        params: thickness map, smoothing and the surface edge length fed to fTetWild.

    Raises:
        NotWatertightError: if the result is not closed and consistently oriented (e.g. the
            skin is non-manifold).
    """
    v, f = remesh_isotropic(skin_vertices, skin_faces, params.surface_edge_length_m, 4)
    n_skin = len(v)
    smooth = _smoothing_operator(f, n_skin)
    normals = vertex_normals(v, f)
    thickness = thickness_map(v, landmarks, params)
    for _ in range(params.normal_smoothing_iterations):
        normals = smooth @ normals
        thickness = smooth @ thickness
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    inner = v - thickness[:, None] * normals

    border = boundary_edges(f)  # (B, 2) a->b as in the skin triangles
    a, b = border[:, 0], border[:, 1]
    rim = np.r_[np.c_[b, a, a + n_skin], np.c_[b, a + n_skin, b + n_skin]]
    faces = np.r_[f, f[:, ::-1] + n_skin, rim]
    part = np.r_[
        np.full(len(f), PART_SKIN), np.full(len(f), PART_BONE), np.full(len(rim), PART_RIM)
    ].astype(np.int8)
    problems = watertight_problems(faces)
    if problems:
        raise NotWatertightError(
            "tissue surface is not watertight: " + "; ".join(problems) + ". Clean the skin "
            "surface (scan_io.clean_scan, remesh.prepare_scan) so it is one manifold sheet"
        )
    surface = TissueSurface(
        vertices=np.r_[v, inner], faces=faces.astype(np.int64), part=part, thickness=thickness
    )
    if surface.enclosed_volume() <= 0.0:
        raise ValueError(
            "tissue volume came out negative: the skin normals point into the head; flip the "
            "skin faces (F[:, ::-1]) so their normals point out of the face (+z)"
        )
    return surface
