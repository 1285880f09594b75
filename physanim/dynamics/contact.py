"""Signed distances between link capsules and the environment (ground plane, boxes).

A capsule is a segment a-b (m) swept by a sphere of radius r (m).  Distances are signed
(negative = penetration depth) and vectorised over capsules.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class Environment:
    """Horizontal ground at ``ground_height`` (m, along ``up``) plus axis-aligned boxes.

    ``boxes``: list of (lo (3,), hi (3,)) corner pairs, m.  ``up`` (3,) must be a
    coordinate axis (default +y).
    """

    ground_height: float = 0.0
    boxes: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)


def box_signed_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Signed distance (...,) m from points p (..., 3) to the box [lo, hi]."""
    centre = 0.5 * (lo + hi)
    d = np.abs(p - centre) - 0.5 * (hi - lo)
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
    return outside + np.minimum(d.max(axis=-1), 0.0)


def capsule_box_distance(
    a: np.ndarray, b: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, iters: int = 60
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance (k,) m of capsules (a, b (k, 3), r (k,)) to a box, and the closest
    axis points (k, 3).  The box distance is convex along a segment, so a golden-section
    search over the segment parameter finds its minimum (to ~1e-12 of the length)."""
    lo_s = np.zeros(len(a))
    hi_s = np.ones(len(a))
    ab = b - a
    for _ in range(iters):
        s1 = hi_s - _GOLDEN * (hi_s - lo_s)
        s2 = lo_s + _GOLDEN * (hi_s - lo_s)
        f1 = box_signed_distance(a + s1[:, None] * ab, lo, hi)
        f2 = box_signed_distance(a + s2[:, None] * ab, lo, hi)
        left = f1 <= f2
        hi_s = np.where(left, s2, hi_s)
        lo_s = np.where(left, lo_s, s1)
    p = a + (0.5 * (lo_s + hi_s))[:, None] * ab
    return box_signed_distance(p, lo, hi) - r, p


def capsule_plane_distance(
    a: np.ndarray, b: np.ndarray, r: np.ndarray, height: float, up: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance (k,) m of capsules above the plane ``x . up = height`` and the
    lowest axis points (k, 3)."""
    ha, hb = a @ up, b @ up
    p = np.where((ha <= hb)[:, None], a, b)
    return np.minimum(ha, hb) - height - r, p


def environment_distance(
    env: Environment, a: np.ndarray, b: np.ndarray, r: np.ndarray
) -> tuple[float, np.ndarray]:
    """Smallest signed distance (m) of any capsule to the environment, and the contact
    point (3,) on the environment's surface nearest to that capsule."""
    up = np.asarray(env.up, dtype=float)
    best, point = capsule_plane_distance(a, b, r, env.ground_height, up)
    point = point - (point @ up - env.ground_height)[:, None] * up
    for lo, hi in env.boxes:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        d, p = capsule_box_distance(a, b, r, lo, hi)
        closer = d < best
        best = np.where(closer, d, best)
        point = np.where(closer[:, None], np.clip(p, lo, hi), point)
    k = int(np.argmin(best))
    return float(best[k]), point[k]
