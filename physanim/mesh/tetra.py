"""Tetrahedralisation of the tissue volume (fTetWild via pytetwild), quality, node labels."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from physanim.mesh.binding import bind_points
from physanim.mesh.params import TetraParams
from physanim.mesh.tissue import PART_BONE, PART_SKIN, TissueSurface


@dataclass(frozen=True)
class Sizing:
    """A graded target tet edge length (:mod:`physanim.mesh.sizing`): ``lengths`` maps points
    (P, 3) m to (P,) m; ``detail`` (D, 3) m are extra points of the background mesh where the
    length varies faster than its coarse grid resolves (about a refined region)."""

    lengths: Callable[[np.ndarray], np.ndarray]
    detail: np.ndarray


#: The 6 edges (i, j) of a tet and the two vertices (k, l) opposite each: the faces opposite k
#: and l meet along edge (i, j).
_EDGES = np.array(
    [[0, 1, 2, 3], [0, 2, 1, 3], [0, 3, 1, 2], [1, 2, 0, 3], [1, 3, 0, 2], [2, 3, 0, 1]]
)
#: Vertices of the face opposite vertex i, ordered so the normal points out of a positive tet.
_OPPOSITE = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


class TetMeshError(ValueError):
    """The tetrahedral mesh is unusable (empty, degenerate tets)."""


@dataclass(frozen=True)
class TetMesh:
    """Tetrahedral mesh: ``nodes`` (n, 3) metres, ``tets`` (m, 4) int64, all positive volume."""

    nodes: np.ndarray
    tets: np.ndarray


@dataclass(frozen=True)
class TetQuality:
    """Quality summary of a tet mesh (angles in degrees, volume in m^3).

    ``n_slivers`` counts tets whose smallest dihedral angle is below ``sliver_dihedral_deg``;
    ``n_inverted_input`` counts tets that came out of the mesher negatively oriented and were
    flipped (fTetWild's own orientation convention is negative, so usually all of them);
    ``attempts`` counts the fTetWild runs made to meet ``TetraParams.min_dihedral_deg``.
    """

    n_nodes: int
    n_tets: int
    volume_m3: float
    min_dihedral_deg: float
    median_dihedral_deg: float
    max_dihedral_deg: float
    max_aspect_ratio: float
    median_aspect_ratio: float
    n_slivers: int
    n_inverted_input: int
    attempts: int = 1

    def as_dict(self) -> dict[str, float | int]:
        """Plain dict for logs and store attributes."""
        return asdict(self)


def tet_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes (m,) of tets (m, 4) over nodes (n, 3); positive when (b-a, c-a, d-a) is
    right-handed. Units: cube of the node unit."""
    p = nodes[tets]
    return (
        np.einsum("mi,mi->m", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
        / 6.0
    )


def dihedral_angles(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Interior dihedral angles (m, 6) in degrees of positively oriented tets (m, 4)."""
    p = nodes[tets]  # (m, 4, 3)
    f = p[:, _OPPOSITE]  # (m, 4, 3, 3)
    n = np.cross(f[:, :, 1] - f[:, :, 0], f[:, :, 2] - f[:, :, 0])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    cos = -np.einsum("mei,mei->me", n[:, _EDGES[:, 2]], n[:, _EDGES[:, 3]])
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def edge_lengths(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Lengths (m, 6) of the 6 edges of tets (m, 4) over nodes (n, 3), in the node unit."""
    p = nodes[tets]
    return np.linalg.norm(p[:, _EDGES[:, 0]] - p[:, _EDGES[:, 1]], axis=2)


def box_grid(lo: np.ndarray, hi: np.ndarray, spacing: float) -> np.ndarray:
    """(G, 3) points of a regular grid of ``spacing`` from ``lo`` (3,) covering ``hi`` (3,)."""
    axes = [np.arange(lo[i], hi[i] + spacing, spacing) for i in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def aspect_ratios(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Aspect ratio (m,) = longest edge / (2 sqrt(6) inradius); 1 for a regular tet."""
    p = nodes[tets]
    edges = edge_lengths(nodes, tets)
    f = p[:, _OPPOSITE]
    areas = 0.5 * np.linalg.norm(
        np.cross(f[:, :, 1] - f[:, :, 0], f[:, :, 2] - f[:, :, 0]), axis=2
    ).sum(axis=1)
    inradius = 3.0 * np.abs(tet_volumes(nodes, tets)) / areas
    return edges.max(axis=1) / (2.0 * np.sqrt(6.0) * inradius)


def orient_and_check(
    nodes: np.ndarray, tets: np.ndarray, params: TetraParams
) -> tuple[np.ndarray, int]:
    """Return tets (m, 4) with positive volume (two nodes swapped where negative) and the count
    that was flipped.

    Raises:
        TetMeshError: on an empty mesh or degenerate tets (|volume| below
            ``degenerate_volume_rel * finest_edge_length_m^3``).
    """
    tets = np.asarray(tets, dtype=np.int64).copy()
    if tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise TetMeshError(f"tets must be a non-empty (m, 4) array, got {tets.shape}")
    vol = tet_volumes(nodes, tets)
    tiny = params.degenerate_volume_rel * params.finest_edge_length_m**3
    bad = np.abs(vol) <= tiny
    if np.any(bad):
        raise TetMeshError(
            f"{int(bad.sum())} degenerate tets (|volume| <= {tiny:.3g} m^3), e.g. tet "
            f"{int(np.argmax(bad))}; re-run with optimize=True or a larger edge_length_m"
        )
    neg = vol < 0.0
    tets[neg] = tets[neg][:, [1, 0, 2, 3]]
    return tets, int(neg.sum())


def quality_report(mesh: TetMesh, params: TetraParams, n_inverted_input: int = 0) -> TetQuality:
    """Tet count, volume, dihedral angles, aspect ratios and slivers of a positive tet mesh."""
    dih = dihedral_angles(mesh.nodes, mesh.tets)
    ar = aspect_ratios(mesh.nodes, mesh.tets)
    return TetQuality(
        n_nodes=len(mesh.nodes),
        n_tets=len(mesh.tets),
        volume_m3=float(tet_volumes(mesh.nodes, mesh.tets).sum()),
        min_dihedral_deg=float(dih.min()),
        median_dihedral_deg=float(np.median(dih)),
        max_dihedral_deg=float(dih.max()),
        max_aspect_ratio=float(ar.max()),
        median_aspect_ratio=float(np.median(ar)),
        n_slivers=int(np.sum(dih.min(axis=1) < params.sliver_dihedral_deg)),
        n_inverted_input=n_inverted_input,
    )


def _polydata(vertices: np.ndarray, faces: np.ndarray) -> Any:
    import pyvista as pv

    return pv.PolyData(
        np.asarray(vertices, dtype=np.float64), np.c_[np.full(len(faces), 3), faces].ravel()
    )


def distance_to_surface(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(P,) m: distance of ``points`` (P, 3) m to the triangles ``vertices`` (N, 3) m,
    ``faces`` (F, 3) (VTK's vtkImplicitPolyDataDistance; its sign is not used: it follows
    the nearest triangle's normal, which is unreliable next to edges)."""
    import pyvista as pv

    pts = pv.PolyData(np.asarray(points, dtype=np.float64))
    return np.abs(pts.compute_implicit_distance(_polydata(vertices, faces))["implicit_distance"])


def inside_closed_surface(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> np.ndarray:
    """(P,) bool: which ``points`` (P, 3) lie inside the closed, outward-oriented surface
    ``vertices`` (N, 3), ``faces`` (F, 3) (VTK's ray-casting vtkSelectEnclosedPoints)."""
    import pyvista as pv
    from vtkmodules.vtkFiltersModeling import vtkSelectEnclosedPoints

    select = vtkSelectEnclosedPoints()
    select.SetInputData(pv.PolyData(np.asarray(points, dtype=np.float64)))
    select.SetSurfaceData(_polydata(vertices, faces))
    select.CheckSurfaceOff()  # the tissue surface is checked watertight when it is built
    select.Update()
    return pv.wrap(select.GetOutput()).point_data["SelectedPoints"].astype(bool)


def sizing_field(
    vertices: np.ndarray,
    faces: np.ndarray,
    params: TetraParams,
    graded: Sizing | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """fTetWild's background mesh: its vertices (B, 3) m, tets (T, 4) int32 and target edge
    length (B,) m: ``graded``'s length at the point (default ``edge_length_m`` everywhere) inside
    the closed surface (``vertices`` (N, 3) m, ``faces`` (F, 3)) and within one edge length
    of it, growing by ``outside_growth`` per metre of distance beyond, up to
    ``outside_edge_length_m``.

    fTetWild meshes the whole bounding box and keeps the tets inside the surface only at the
    end; for a thin curved shell such as the face's tissue most of its work went into tets
    it then discarded (measured: about 85 %). A coarse target outside halves its time."""
    far = params.ftetwild_edge_length_m
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    # fTetWild's box extends 1/15 of the largest extent beyond the surface; a point outside
    # the background mesh would get its global (coarse) length
    margin = 0.25 * float((hi - lo).max()) + far
    grid = box_grid(lo - margin, hi + margin, 0.5 * far)
    if graded is not None:
        grid = np.r_[grid, graded.detail]
    points = np.r_[vertices, grid]
    h = (
        np.full(len(points), params.edge_length_m)
        if graded is None
        else np.asarray(graded.lengths(points), dtype=np.float64)
    )
    hg = h[len(vertices) :]
    distance = distance_to_surface(grid, vertices, faces)
    values = np.clip(hg + params.outside_growth * (distance - hg), hg, max(far, hg.max()))
    inside = inside_closed_surface(grid, vertices, faces)
    values[inside] = hg[inside]
    tets = Delaunay(points).simplices.astype(np.int32)
    return points, tets, np.r_[h[: len(vertices)], values]


def tetrahedralize_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    params: TetraParams,
    graded: Sizing | None = None,
) -> tuple[TetMesh, TetQuality]:
    """Tetrahedralise a closed surface with fTetWild at ``graded``'s lengths inside (default
    ``params.edge_length_m``; :mod:`physanim.mesh.sizing` grades it by region), coarser
    outside where its tets are discarded (:func:`sizing_field`).

    fTetWild is not deterministic; while its mesh's smallest dihedral angle is below
    ``params.min_dihedral_deg`` it runs again, up to ``params.mesh_attempts`` runs, and the
    best mesh is kept (a warning says when none met the floor).

    Args:
        vertices: (N, 3) closed surface, metres; faces: (M, 3) int.
        params: edge length, envelope, optimisation and quality thresholds.

    Returns:
        The positively oriented :class:`TetMesh` (no unused nodes) and its :class:`TetQuality`.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int32)
    sizing: dict[str, np.ndarray] = {}
    if graded is not None or params.ftetwild_edge_length_m > params.edge_length_m:
        bg_vertices, bg_tets, bg_values = sizing_field(vertices, faces, params, graded)
        sizing = {"bg_vertices": bg_vertices, "bg_tets": bg_tets, "bg_values": bg_values}
    runs: list[tuple[TetMesh, TetQuality]] = []
    while len(runs) < params.mesh_attempts:
        runs.append(_ftetwild(vertices, faces, params, sizing))
        if runs[-1][1].min_dihedral_deg >= params.min_dihedral_deg:
            break
    mesh, quality = max(runs, key=lambda run: run[1].min_dihedral_deg)
    quality = replace(quality, attempts=len(runs))
    if quality.min_dihedral_deg < params.min_dihedral_deg:
        warnings.warn(
            f"fTetWild's best of {len(runs)} meshes has a {quality.min_dihedral_deg:.2f} deg "
            f"dihedral angle, below tetra.min_dihedral_deg = {params.min_dihedral_deg} deg; "
            "raise tetra.mesh_attempts or tetra.max_opt_iterations",
            RuntimeWarning,
            stacklevel=2,
        )
    return mesh, quality


def enclosed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume (m^3) enclosed by a closed, outward-oriented triangle surface (N, 3) / (M, 3)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def load_tet_mesh(
    path: str | Path, vertices: np.ndarray, faces: np.ndarray, params: TetraParams
) -> tuple[TetMesh, TetQuality]:
    """The tet mesh saved in ``path`` (.npz: ``nodes`` (n, 3) m, ``tets`` (m, 4)) as the mesh
    of the closed surface ``vertices`` (N, 3) m / ``faces`` (M, 3): oriented and checked as
    fTetWild's. ValueError naming the file when it is unreadable or does not fill that
    surface (volumes more than 5 % apart: a mesh of another tissue)."""
    path = Path(path)
    try:
        with np.load(path) as data:
            nodes = np.asarray(data["nodes"], dtype=np.float64)
            tets = np.asarray(data["tets"], dtype=np.int64)
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(
            f"tetra.mesh_file {path}: not an .npz with 'nodes' and 'tets' ({exc})"
        ) from None
    if nodes.ndim != 2 or nodes.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4:
        raise ValueError(
            f"tetra.mesh_file {path}: nodes {nodes.shape} and tets {tets.shape} must be "
            "(n, 3) and (m, 4)"
        )
    if tets.size == 0 or tets.min() < 0 or tets.max() >= len(nodes):
        raise ValueError(f"tetra.mesh_file {path}: tets index outside the {len(nodes)} nodes")
    tets, flipped = orient_and_check(nodes, tets, params)
    mesh = TetMesh(nodes=nodes, tets=tets)
    quality = quality_report(mesh, params, flipped)
    target = abs(enclosed_volume(vertices, faces))
    if not abs(quality.volume_m3 - target) <= 0.05 * target:
        raise ValueError(
            f"tetra.mesh_file {path}: its volume {quality.volume_m3 * 1e6:.1f} cm^3 is not the "
            f"tissue's {target * 1e6:.1f} cm^3: a mesh of another scan or tissue settings; "
            "remove tetra.mesh_file to mesh this one"
        )
    return mesh, replace(quality, attempts=0)


def _ftetwild(
    vertices: np.ndarray, faces: np.ndarray, params: TetraParams, sizing: dict[str, np.ndarray]
) -> tuple[TetMesh, TetQuality]:
    """One fTetWild run on the surface (N, 3) m / (M, 3) int32 with the background ``sizing``
    mesh (empty: uniform), oriented and checked."""
    import pytetwild  # imports pyvista at load time

    nodes, tets = pytetwild.tetrahedralize(
        vertices,
        faces,
        edge_length_abs=params.ftetwild_edge_length_m,
        epsilon=params.epsilon_rel,
        optimize=params.optimize,
        stop_energy=params.stop_energy,
        num_opt_iter=params.max_opt_iterations,
        quiet=True,
        **sizing,
    )
    tets = np.asarray(tets, dtype=np.int64)
    if len(tets) == 0:
        raise TetMeshError(
            "fTetWild returned no tets: the surface encloses no volume at this edge length; "
            "check that it is closed or lower edge_length_m"
        )
    used, inverse = np.unique(tets, return_inverse=True)
    nodes = np.asarray(nodes, dtype=np.float64)[used]
    tets, flipped = orient_and_check(nodes, inverse.reshape(tets.shape), params)
    mesh = TetMesh(nodes=nodes, tets=tets)
    return mesh, quality_report(mesh, params, flipped)


def boundary_faces_and_tets(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(B, 3) faces of positive tets (m, 4) used by one tet only, oriented outward, and the
    tet (B,) each belongs to."""
    faces = tets[:, _OPPOSITE].reshape(-1, 3)
    _, inverse, counts = np.unique(
        np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True
    )
    once = counts[inverse.ravel()] == 1
    return faces[once], np.repeat(np.arange(len(tets)), 4)[once]


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """(B, 3) faces of positive tets (m, 4) used by one tet only, oriented outward."""
    return boundary_faces_and_tets(tets)[0]


@dataclass(frozen=True)
class NodeLabels:
    """Node labels of a tissue tet mesh.

    Attributes:
        skin: (n,) bool, boundary nodes on the skin surface.
        bone: (n,) bool, boundary nodes on the bone-side surface (skull or mandible in the FEM).
    """

    skin: np.ndarray
    bone: np.ndarray


def label_nodes(mesh: TetMesh, surface: TissueSurface, params: TetraParams) -> NodeLabels:
    """Label skin / bone-side boundary nodes of a tissue tet mesh.

    Args:
        mesh: the tissue tet mesh.
        surface: the tissue surface it was built from (face parts tell skin from bone).
        params: ``label_tolerance_rel`` (times ``edge_length_m``) decides on-surface.
    """
    tol = params.label_tolerance_rel * params.edge_length_m
    on_boundary = np.zeros(len(mesh.nodes), dtype=bool)
    on_boundary[boundary_faces(mesh.tets).ravel()] = True
    idx = np.nonzero(on_boundary)[0]
    pts = mesh.nodes[idx]

    def near(part: int) -> np.ndarray:
        d = bind_points(pts, surface.vertices, surface.faces[surface.part == part]).distance
        out = np.zeros(len(mesh.nodes), dtype=bool)
        out[idx[d <= tol]] = True
        return out

    skin = near(PART_SKIN)
    if not skin.any():
        raise TetMeshError("no tet node lies on the skin surface; check label_tolerance_rel")
    return NodeLabels(skin=skin, bone=near(PART_BONE) & ~skin)


def landmark_nodes(
    nodes: np.ndarray,
    skin: np.ndarray,
    node_side: np.ndarray,
    landmarks: np.ndarray,
    landmark_side: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The nearest skin node (K,) of each landmark (K, 3) m on its own side of the lip seam
    (sides as in :mod:`physanim.mesh.seam`), and the distance (K,) m to it."""
    lm = np.asarray(landmarks, dtype=np.float64).reshape(-1, 3)
    skin_idx = np.nonzero(skin)[0]
    d = np.linalg.norm(nodes[skin_idx][None] - lm[:, None], axis=2)  # (K, S)
    wrong = (np.asarray(landmark_side)[:, None] * node_side[skin_idx][None]) < 0
    d[wrong] = np.inf
    j = np.argmin(d, axis=1)
    return skin_idx[j], d[np.arange(len(lm)), j]


def skin_anchors(nodes: np.ndarray, bone: np.ndarray, surface: TissueSurface) -> np.ndarray:
    """(n, 3) m: for each bone-side node, the skin point it lies behind (the bone-side
    surface is the skin moved inward, vertex by vertex); other nodes: their own position."""
    n_skin = surface.n_skin
    inner = surface.vertices[n_skin:]
    out = np.array(nodes, dtype=np.float64)
    b = np.nonzero(bone)[0]
    _, j = cKDTree(inner).query(out[b])
    out[b] = surface.vertices[:n_skin][j]
    return out
