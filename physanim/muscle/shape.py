"""Volume-preserving spindle muscle bellies coloured by activation (seed 000 section 5.1).

Each belly is an ellipsoid of revolution centred between the attachment points, its long axis
on the line of action.  At optimal length its semi-axes are l0 / 2 and r0, with the
physiological cross-section pi r0^2 = F0 / sigma (sigma ~ 3.5 kgf/cm^2, seed eq 19), so its
volume is V = (2/3) pi r0^2 l0 (eq 20).  As the fibre length l^M changes the long semi-axis
is l^M / 2 and the short one sqrt(3 V / (2 pi l^M)) keeps V constant (eqs 21-23).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def spindle_volume(
    max_isometric_force: ArrayLike, optimal_fibre_length: ArrayLike, specific_tension: float
) -> NDArray[np.float64]:
    """Belly volume (m,) m^3 from F0 (m,) N, l0 (m,) m and the specific tension in Pa."""
    area = np.asarray(max_isometric_force, dtype=float) / specific_tension
    return 2.0 / 3.0 * area * np.asarray(optimal_fibre_length, dtype=float)


def spindle_semi_axes(
    fibre_length: ArrayLike, volume: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Long and short semi-axes (each like fibre_length, e.g. (T, m)) m of the spindle.

    fibre_length (T, m) m, volume (m,) m^3; (4/3) pi long short^2 = volume.
    """
    long = 0.5 * np.asarray(fibre_length, dtype=float)
    return long, np.sqrt(3.0 * np.asarray(volume, dtype=float) / (4.0 * np.pi * long))


def spindle_mesh(
    centre: ArrayLike,
    axis: ArrayLike,
    long: float,
    short: float,
    n_around: int = 16,
    n_along: int = 17,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Closed triangle mesh of an ellipsoid of revolution, normals outwards.

    centre (3,) m, axis (3,) direction of the long axis, semi-axes ``long`` and ``short`` m;
    ``n_along`` rings (>= 3, counting the two poles) of ``n_around`` vertices.  Returns
    vertices (2 + (n_along - 2) n_around, 3) m and faces (F, 3).
    """
    e = np.asarray(axis, dtype=float)
    e = e / np.linalg.norm(e)
    helper = np.array([0.0, 0.0, 1.0]) if abs(e[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(e, helper)
    u /= np.linalg.norm(u)
    w = np.cross(e, u)
    polar = np.linspace(0.0, np.pi, n_along)[1:-1]
    phi = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
    ring = (
        short
        * np.sin(polar)[:, None, None]
        * (np.cos(phi)[None, :, None] * u + np.sin(phi)[None, :, None] * w)
    )
    body = long * np.cos(polar)[:, None, None] * e + ring
    c = np.asarray(centre, dtype=float)
    vertices = np.concatenate([[c + long * e], c + body.reshape(-1, 3), [c - long * e]])

    n_r = n_along - 2
    idx = 1 + np.arange(n_r * n_around).reshape(n_r, n_around)
    nxt = np.roll(idx, -1, axis=1)
    top = np.stack([np.zeros(n_around, int), idx[0], nxt[0]], 1)
    bottom = np.stack([np.full(n_around, len(vertices) - 1), nxt[-1], idx[-1]], 1)
    quads_a = np.stack([idx[:-1], nxt[1:], nxt[:-1]], -1).reshape(-1, 3)
    quads_b = np.stack([idx[:-1], idx[1:], nxt[1:]], -1).reshape(-1, 3)
    faces = np.concatenate([top, quads_a, quads_b, bottom]).astype(np.int64)
    return vertices, faces


def mesh_volume(vertices: ArrayLike, faces: ArrayLike) -> float:
    """Volume enclosed by a closed, outward-oriented triangle mesh (divergence theorem), m^3."""
    t = np.asarray(vertices, dtype=float)[np.asarray(faces)]
    return float(np.einsum("fi,fi->", t[:, 0], np.cross(t[:, 1], t[:, 2])) / 6.0)


def activation_colour(activation: ArrayLike) -> NDArray[np.float64]:
    """RGB in [0, 1], (..., 3): (1, 1 - a, 1 - a), white at rest, red at full activation."""
    a = np.clip(np.asarray(activation, dtype=float), 0.0, 1.0)
    return np.stack([np.ones_like(a), 1.0 - a, 1.0 - a], axis=-1)
