"""Structured tet meshes for the FEM tests (boxes and a thick-walled cylinder sector)."""

from __future__ import annotations

from itertools import permutations

import numpy as np

from physanim.fem.geometry import signed_volumes


def box_mesh(
    shape: tuple[int, int, int], size: tuple[float, float, float] = (1.0, 1.0, 1.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Box [0, size] split into shape[0] x shape[1] x shape[2] cubes of 6 Kuhn tets each.

    Returns nodes (N, 3) and positively oriented tets (M, 4).
    """
    nx, ny, nz = shape
    axes = [np.linspace(0.0, s, k + 1) for s, k in zip(size, shape, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nx + 1, ny + 1, nz + 1)
    base = idx[:-1, :-1, :-1].ravel()
    step = np.array([(ny + 1) * (nz + 1), nz + 1, 1])
    tets = []
    for perm in permutations(range(3)):  # paths 000 -> 111 along the axes in this order
        offs = [0]
        for ax in perm:
            offs.append(offs[-1] + step[ax])
        tets.append(base[:, None] + np.array(offs)[None])
    tets = np.concatenate(tets)
    neg = signed_volumes(grid, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return grid, tets.astype(np.int64)


def cylinder_sector(
    a: float, b: float, n_r: int, n_theta: int, height: float, n_z: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quarter of a thick-walled cylinder (inner radius a, outer b, m) as structured tets.

    Returns nodes (N, 3), tets (M, 4) and (r, theta, z) of each node (N, 3).
    """
    param, tets = box_mesh((n_r, n_theta, n_z), (b - a, np.pi / 2, height))
    r, th, z = param[:, 0] + a, param[:, 1], param[:, 2]
    nodes = np.stack([r * np.cos(th), r * np.sin(th), z], axis=1)
    neg = signed_volumes(nodes, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return nodes, tets, np.stack([r, th, z], axis=1)


def lame_cylinder_ur(r: np.ndarray, a: float, b: float, p: float, E: float, nu: float):
    """Exact radial displacement (m) of a plane-strain thick cylinder, internal pressure p."""
    return (1 + nu) * p * a**2 / (E * (b**2 - a**2)) * ((1 - 2 * nu) * r + b**2 / r)
