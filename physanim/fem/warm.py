"""Compile the FEM's numba kernels ahead of the first run (``python -m physanim.warm`` runs
``warm_kernels`` with the project's other kernels; see there).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import Delaunay

from physanim.fem.geometry import signed_volumes
from physanim.fem.linsolve import has_cholmod
from physanim.fem.materials import TetMaterials
from physanim.fem.params import SimulateParams
from physanim.fem.simulate import simulate


def _small_slab() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 4 x 4 x 1 cm slab of Delaunay tets: nodes (N, 3) m, tets (M, 4), the bottom nodes
    (fixed) and the top middle ones (driven)."""
    axes = (np.linspace(0, 0.04, 5), np.linspace(0, 0.04, 5), np.linspace(0, 0.01, 3))
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inner = (nodes > 0).all(axis=1) & (nodes < [0.04, 0.04, 0.01]).all(axis=1)
    nodes[inner] += np.random.default_rng(0).uniform(-5e-4, 5e-4, (int(inner.sum()), 3))
    tets = Delaunay(nodes).simplices.astype(np.int64)
    vol = signed_volumes(nodes, tets)
    keep = np.abs(vol) > 1e-12
    tets, neg = tets[keep], vol[keep] < 0
    tets[neg] = tets[neg][:, [1, 0, 2, 3]]
    top = np.flatnonzero(np.isclose(nodes[:, 2], 0.01))
    driven = top[np.linalg.norm(nodes[top, :2] - 0.02, axis=1) < 0.011]
    return nodes, tets, np.flatnonzero(nodes[:, 2] == 0), driven


def warm_kernels() -> dict[str, float]:
    """Run a small adaptive ``simulate`` (a jerk, so step sizes change) with each factor
    precision the runs use; returns the seconds each took (compiling or loading)."""
    nodes, tets, fixed, driven = _small_slab()
    pulse = np.r_[0.0, 0.0, 0.5, 1.0, 1.0, 1.0]
    traj = np.zeros((len(pulse), len(driven), 3))
    traj[:, :, 2] = 1e-3 * pulse[:, None]
    materials = TetMaterials.uniform(len(tets))
    seconds = {}
    for precision in ("float32", "float64") if has_cholmod() else ("float64",):
        t0 = time.perf_counter()
        params = SimulateParams(dt=2.5e-3, error_tol_mm=1e-3, precision=precision)
        simulate(nodes, tets, materials, driven, traj, 1 / 30, fixed, params)
        seconds[precision] = time.perf_counter() - t0
    return seconds
