"""Regional refinement: the target tet edge length over the tissue (``tetra.refine``).

fTetWild takes a background mesh with a target edge length at its points
(:func:`physanim.mesh.tetra.sizing_field`); this module says what that length is inside and
near the tissue: a named region's length within its radius of any of its feature points,
graded linearly over ``blend_m`` into ``edge_length_m`` at the skin elsewhere, and from there
to ``deep_edge_length_m`` at ``deep_depth_m`` below the skin outside every region.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy.spatial import cKDTree

from physanim.mesh.params import RefineParams, RefineRegion, TetraParams
from physanim.mesh.tetra import Sizing, box_grid, dihedral_angles, edge_lengths


def _centres(name: str, region: RefineRegion, landmarks: Mapping[str, np.ndarray]) -> np.ndarray:
    """(K, 3) m: the feature points region ``name`` surrounds; ValueError naming the config
    key when ``landmarks`` lacks one."""
    missing = [n for n in region.landmarks if n not in landmarks]
    if missing:
        raise ValueError(
            f"tetra.refine.regions.{name}.landmarks: {missing} not among the aligned "
            f"feature points {sorted(landmarks)}"
        )
    return np.array([landmarks[n] for n in region.landmarks], dtype=np.float64)


def region_weights(
    points: np.ndarray, landmarks: Mapping[str, np.ndarray], refine: RefineParams
) -> dict[str, np.ndarray]:
    """Region name -> (P,) weight in [0, 1] of points (P, 3) m: 1 within ``radius_m`` of any
    of the region's feature points, falling linearly to 0 at ``radius_m + blend_m``.

    Raises:
        ValueError: a region names a feature point ``landmarks`` lacks.
    """
    out = {}
    for name, region in refine.regions.items():
        centres = _centres(name, region, landmarks)
        distance = cKDTree(centres).query(np.asarray(points, dtype=np.float64))[0]
        out[name] = np.clip(1.0 - (distance - region.radius_m) / refine.blend_m, 0.0, 1.0)
    return out


def detail_points(landmarks: Mapping[str, np.ndarray], refine: RefineParams) -> np.ndarray:
    """(D, 3) m: a grid at half ``blend_m`` spacing over every region's ball of radius
    ``radius_m + blend_m`` about its feature points, where the length grades faster than
    fTetWild's background grid (half the coarse outside length) resolves."""
    if not refine.regions:
        return np.zeros((0, 3))
    balls = [(_centres(name, region, landmarks), region.radius_m + refine.blend_m)
             for name, region in refine.regions.items()]  # fmt: skip
    c = np.concatenate([centres for centres, _ in balls])
    r = np.concatenate([np.full(len(centres), reach) for centres, reach in balls])
    lo, hi = (c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0)
    grid = box_grid(lo, hi, 0.5 * refine.blend_m)
    near = np.zeros(len(grid), dtype=bool)
    for centre, radius in zip(c, r, strict=True):
        near |= np.linalg.norm(grid - centre, axis=1) <= radius
    return grid[near]


def regional_sizing(
    skin_vertices: np.ndarray, landmarks: Mapping[str, np.ndarray], params: TetraParams
) -> Sizing:
    """The target edge length inside and near the tissue of ``params.refine``.

    Args:
        skin_vertices: (S, 3) skin surface of the tissue, metres (depth is measured to them).
        landmarks: feature point name -> (3,) position, metres.
        params: ``edge_length_m`` (the skin's length outside every region) and ``refine``.

    Returns:
        The :class:`Sizing` whose lengths at points (P, 3) m are (P,) m: the smallest of the
        regions' graded lengths, and outside the regions the deep length reached linearly
        over the depth; its detail points resolve the regions (:func:`detail_points`).

    Raises:
        ValueError: a region names a feature point ``landmarks`` lacks.
    """
    refine = params.refine
    h = params.edge_length_m
    skin = cKDTree(np.asarray(skin_vertices, dtype=np.float64))

    def lengths(points: np.ndarray) -> np.ndarray:
        size = np.full(len(points), h)
        inside = np.zeros(len(points))
        for name, w in region_weights(points, landmarks, refine).items():
            size = np.minimum(size, h + w * (refine.regions[name].edge_length_m - h))
            inside = np.maximum(inside, w)
        if refine.deep_edge_length_m is not None:
            depth = skin.query(np.asarray(points, dtype=np.float64))[0]
            s = np.clip(depth / refine.deep_depth_m, 0.0, 1.0) * (1.0 - inside)
            size = size + s * np.maximum(refine.deep_edge_length_m - size, 0.0)
        return size

    return Sizing(lengths, detail_points(landmarks, refine))


def region_quality(
    nodes: np.ndarray,
    tets: np.ndarray,
    landmarks: Mapping[str, np.ndarray],
    refine: RefineParams,
) -> dict[str, dict[str, float | int]]:
    """Per refinement region (tets whose centroid has weight 1, see :func:`region_weights`)
    and for the rest ('elsewhere'): tet count, median edge length (mm) and smallest dihedral
    angle (deg) of positive tets (m, 4) over nodes (n, 3) m."""
    edges = edge_lengths(nodes, tets)
    weights = region_weights(nodes[tets].mean(axis=1), landmarks, refine)
    members = {name: w >= 1.0 for name, w in weights.items()}
    elsewhere = np.ones(len(tets), dtype=bool)
    for m in members.values():
        elsewhere &= ~m
    members["elsewhere"] = elsewhere
    out = {}
    for name, m in members.items():
        if not m.any():
            out[name] = {"tets": 0, "median_edge_mm": None, "min_dihedral_deg": None}
            continue
        out[name] = {
            "tets": int(m.sum()),
            "median_edge_mm": round(float(np.median(edges[m])) * 1e3, 3),
            "min_dihedral_deg": round(float(dihedral_angles(nodes, tets[m]).min()), 2),
        }
    return out
