"""Load and clean triangle-mesh scans (PLY/OBJ/STL) into metres.

Vertices are ``(N, 3)`` float64 metres, faces ``(M, 3)`` int64 vertex indices.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
import pymeshlab
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

Units = Literal["mm", "cm", "m"]

#: Metres per unit of each supported scan unit.
UNIT_SCALE: dict[str, float] = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}

#: Plausible size of a face scan: largest bounding-box extent, metres.
FACE_EXTENT_RANGE_M: tuple[float, float] = (0.05, 0.6)

SUPPORTED_SUFFIXES = (".ply", ".obj", ".stl")


class ScanError(ValueError):
    """A scan file cannot be used: unreadable, empty, or implausibly sized."""


def face000_path() -> Path:
    """Path of the real face range scan shipped with pymeshlab (85,849 vertices, in mm)."""
    path = Path(pymeshlab.__file__).parent / "tests/sample_meshes/rangemaps/face000.ply"
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: pymeshlab's sample face scan is missing; reinstall pymeshlab "
            "(pip install --force-reinstall pymeshlab)"
        )
    return path


def _read_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) float64 and faces (M, 3) int64 of a PLY/OBJ/STL file, as stored.

    Read by Open3D, not pymeshlab: pymeshlab's loader changes the process's working directory
    to the file's folder while it reads, and a relative path opened by another thread in that
    moment (the run's stages run side by side) names the wrong file. STL repeats each
    triangle's corners: shared corners are merged into one vertex."""
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(str(path), enable_post_processing=False)
    if path.suffix.lower() == ".stl":
        mesh.remove_duplicated_vertices()
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int64)


def load_scan(path: Path | str, units: Units) -> tuple[np.ndarray, np.ndarray]:
    """Load a triangle-mesh scan and convert it to metres.

    ``units`` is the unit of the file's coordinates. Raises ``ScanError`` if the file
    cannot be read, has no triangles, or its size is not that of a face (~0.1-0.3 m)
    in the given unit; the message suggests the unit that would fit.
    Returns ``(vertices (N, 3) float64 m, faces (M, 3) int64)``.
    """
    path = Path(path)
    if units not in UNIT_SCALE:
        raise ValueError(f"units={units!r}: expected one of {sorted(UNIT_SCALE)}")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: scan file not found")
    if path.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise ScanError(f"{path}: unsupported scan format; use one of {SUPPORTED_SUFFIXES}")
    vertices, faces = _read_mesh(path)
    if len(vertices) == 0:
        raise ScanError(f"{path}: cannot read a triangle mesh from the file (damaged?)")
    vertices = vertices * UNIT_SCALE[units]
    if len(faces) == 0 or len(vertices) < 3:
        raise ScanError(f"{path}: the mesh has no triangles (a point cloud is not supported)")
    extent = float(np.ptp(vertices, axis=0).max())
    lo, hi = FACE_EXTENT_RANGE_M
    if not lo <= extent <= hi:
        raw = extent / UNIT_SCALE[units]
        fits = [u for u, s in UNIT_SCALE.items() if lo <= raw * s <= hi]
        hint = f"; try units={fits[0]!r}" if fits else ""
        raise ScanError(
            f"{path}: with units={units!r} the scan is {extent:.3g} m across, but a face scan "
            f"is {lo}-{hi} m across{hint}"
        )
    return vertices, faces


def largest_component(
    faces: np.ndarray, n_vertices: int, weights: np.ndarray | None = None
) -> np.ndarray:
    """Faces ``(M', 3)`` of the largest vertex-connected component: by face count, or by the
    sum of the faces' ``weights`` (M,) (their areas, say)."""
    rows = faces[:, [0, 1, 2]].ravel()
    cols = faces[:, [1, 2, 0]].ravel()
    adj = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    _, labels = connected_components(adj, directed=False)
    face_label = labels[faces[:, 0]]
    counts = np.bincount(face_label, weights=weights)
    return faces[face_label == np.argmax(counts)]


def drop_unreferenced(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used, inverse = np.unique(faces, return_inverse=True)
    return vertices[used], inverse.reshape(faces.shape).astype(np.int64)


def clean_scan(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    max_hole_edges: int = 30,
    crop_radius_m: float | None = None,
    crop_center: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Clean a scan: crop, keep the largest component, drop bad faces, close small holes.

    ``vertices`` (N, 3) m, ``faces`` (M, 3). With ``crop_radius_m``, keeps only faces whose
    three vertices lie within that distance (m) of ``crop_center`` (3,) m (default: the
    vertex centroid). Removes duplicate and zero-area faces and non-manifold edges, then
    closes holes bounded by at most ``max_hole_edges`` edges (0 disables).
    Returns ``(V (N', 3) float64 m, F (M', 3) int64)`` with no unreferenced vertices.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices: expected shape (N, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"faces: expected a non-empty (M, 3) array, got {faces.shape}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError("faces: indices out of range of vertices")
    if crop_radius_m is not None:
        centre = vertices.mean(axis=0) if crop_center is None else np.asarray(crop_center)
        inside = np.linalg.norm(vertices - centre, axis=1) <= crop_radius_m
        faces = faces[inside[faces].all(axis=1)]
        if len(faces) == 0:
            raise ValueError(f"crop_radius_m={crop_radius_m}: no face lies inside the crop")
    # Degenerate (repeated index or zero area) and duplicate faces.
    tri = vertices[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2])
    repeated |= faces[:, 0] == faces[:, 2]
    faces = faces[~repeated & (area2 > 0.0)]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    faces = faces[np.sort(first)]
    faces = largest_component(faces, len(vertices))
    vertices, faces = drop_unreferenced(vertices, faces)

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
    ms.meshing_repair_non_manifold_edges(method="Remove Faces")
    ms.meshing_repair_non_manifold_vertices()
    if max_hole_edges > 0:
        ms.meshing_close_holes(maxholesize=int(max_hole_edges), selfintersection=False)
    ms.meshing_remove_unreferenced_vertices()
    mesh = ms.current_mesh()
    vertices = np.asarray(mesh.vertex_matrix(), dtype=np.float64)
    faces = largest_component(np.asarray(mesh.face_matrix(), dtype=np.int64), len(vertices))
    return drop_unreferenced(vertices, faces)
