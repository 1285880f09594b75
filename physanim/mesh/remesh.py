"""Isotropic remeshing of a cleaned scan to a target edge length (pymeshlab)."""

from __future__ import annotations

import numpy as np
import pymeshlab

from physanim.mesh.notches import close_border_notches, fair_zips
from physanim.mesh.opening import drop_thin_parts
from physanim.mesh.scan_io import FACE_EXTENT_RANGE_M, drop_unreferenced, largest_component
from physanim.mesh.topology import boundary_edges


def remesh_isotropic(
    vertices: np.ndarray, faces: np.ndarray, edge_length_m: float, iterations: int = 6
) -> tuple[np.ndarray, np.ndarray]:
    """Remesh a triangle surface to near-equilateral triangles of a target edge length.

    Args:
        vertices: (N, 3) cleaned scan vertices, metres (see ``scan_io.load_scan``).
        faces: (M, 3) int triangles.
        edge_length_m: target edge length, metres.
        iterations: remeshing passes.

    Returns:
        (V (N', 3) float64 metres, F (M', 3) int64), the open border kept in place and
        non-manifold vertices split so the border loops are simple.

    Raises:
        ValueError: if the surface is not face-sized in metres (a mm/m mix-up) or the target
            edge length is not small against it.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(
            f"vertices must be (N, 3) and faces (M, 3); got {vertices.shape}, {faces.shape}"
        )
    extent = float(np.ptp(vertices, axis=0).max())
    lo, hi = FACE_EXTENT_RANGE_M
    if not lo <= extent <= hi:
        raise ValueError(
            f"scan vertices span {extent:.4g} across, but a face in metres spans {lo}-{hi} m: "
            "the scan is probably not in metres; load it with scan_io.load_scan(path, units) "
            "and the right units"
        )
    if not 0.0 < edge_length_m <= 0.1 * extent:
        raise ValueError(
            f"edge_length_m={edge_length_m} must be in (0, {0.1 * extent:.3g}] m for a scan "
            f"{extent:.3g} m across (is it in metres?)"
        )
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
    ms.meshing_isotropic_explicit_remeshing(
        iterations=int(iterations),
        targetlen=pymeshlab.PureValue(float(edge_length_m)),
        featuredeg=180.0,
        checksurfdist=True,
        maxsurfdist=pymeshlab.PureValue(0.25 * float(edge_length_m)),
    )
    ms.meshing_repair_non_manifold_edges(method="Remove Faces")
    ms.meshing_repair_non_manifold_vertices()
    ms.meshing_remove_unreferenced_vertices()
    mesh = ms.current_mesh()
    return (
        np.asarray(mesh.vertex_matrix(), dtype=np.float64),
        np.asarray(mesh.face_matrix(), dtype=np.int64),
    )


def border_loop_sizes(faces: np.ndarray) -> np.ndarray:
    """Edge counts (L,) of the open border loops of (F, 3) triangles, largest first."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    be = boundary_edges(faces)
    if len(be) == 0:
        return np.zeros(0, dtype=np.int64)
    n = int(be.max()) + 1
    adj = sp.coo_array((np.ones(len(be)), (be[:, 0], be[:, 1])), shape=(n, n))
    _, label = connected_components(adj, directed=False)
    counts = np.bincount(label[be[:, 0]])
    return np.sort(counts[counts > 0])[::-1]


def close_inner_holes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fill every border loop of a surface except the longest (the outer border of the face).

    Args:
        vertices: (N, 3) metres; faces: (M, 3) int.

    Returns:
        (V (N', 3) metres, F (M', 3) int64) with a single open border where the input had one
        outer border plus holes (eyes, occlusions under the nose).
    """
    loops = border_loop_sizes(faces)
    if len(loops) <= 1:
        return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.asarray(vertices, dtype=np.float64),
            face_matrix=np.asarray(faces, dtype=np.int32),
        )
    )
    ms.meshing_close_holes(maxholesize=int(loops[0]) - 1, selfintersection=False)
    mesh = ms.current_mesh()
    return (
        np.asarray(mesh.vertex_matrix(), dtype=np.float64),
        np.asarray(mesh.face_matrix(), dtype=np.int64),
    )


def prepare_scan(
    vertices: np.ndarray,
    faces: np.ndarray,
    edge_length_m: float,
    iterations: int = 6,
    notch_max_gap_m: float = 0.0,
    notch_min_depth_m: float = 0.008,
    min_width_m: float = 0.0,
    notch_fair_band_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Scan preparation after ``scan_io.clean_scan``: drop thin parts, close inner holes and
    border notches, remesh isotropically.

    Args:
        vertices: (N, 3) cleaned scan, metres; faces: (M, 3) int.
        edge_length_m: target edge length, metres (``ScanParams.remesh_edge_length_m``).
        iterations: remeshing passes.
        notch_max_gap_m, notch_min_depth_m: slits reaching in from the border narrower than
            the gap and deeper than the depth (metres) are zipped shut
            (:func:`physanim.mesh.notches.close_border_notches`); a gap of 0 keeps them.
        notch_fair_band_m: the surface within this distance (m) of a zipped notch is faired
            into a ramp (:func:`physanim.mesh.notches.fair_zips`); 0 keeps the zip's wall.
        min_width_m: parts of the scan narrower than this along its outer border, or joined
            to it through a narrower neck, are dropped first
            (:func:`physanim.mesh.opening.drop_thin_parts`); 0 keeps them.

    Returns:
        (V (N', 3) metres, F (M', 3) int64): one component with one open border.
    """
    faces = drop_thin_parts(vertices, faces, min_width_m)
    vertices, faces = drop_unreferenced(vertices, largest_component(faces, len(vertices)))
    v, f = close_inner_holes(*remesh_isotropic(vertices, faces, 2.0 * edge_length_m, 2))
    if notch_max_gap_m > 0:
        zipped, _ = close_border_notches(v, f, notch_max_gap_m, notch_min_depth_m)
        v = fair_zips(v, zipped, np.arange(len(zipped)) >= len(f), notch_fair_band_m)
        f = zipped
    return remesh_isotropic(v, f, edge_length_m, iterations)
