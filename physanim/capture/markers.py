"""Painted markers on the demo actor: names, placement on the surface, and trajectories.

The feature points (``physanim.face.landmarks.FEATURE_POINTS``) and the extra points were
placed by careful inspection: the cleaned face000 actor was rendered (shaded, near-
orthographic along -z, 8 px/mm) with a 5 mm grid of actor (x, y); each point's (x, y)
was read off that render (eye corners, lowest lower-lid points, nose wings, philtrum
ridges, mouth corners at the ends of the lip line, ...). At run time each (x, y) is cast
along -z onto the actor surface (frontmost hit), so the markers sit exactly on the skin.
The pronasale is the actor-frame origin by construction. The scan's face is small
(outer eye corners ~62 mm apart) and its lower face has scan holes; points avoid them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Marker name -> actor-frame (x, y) in millimetres on the neutral face000 actor.
MARKER_XY_MM: dict[str, tuple[float, float]] = {
    "glabella": (0.0, 47.0),
    "ex_L": (31.0, 40.0),
    "ex_R": (-31.0, 39.0),
    "pi_L": (19.0, 32.0),
    "pi_R": (-20.0, 31.0),
    "pronasale": (0.0, 0.0),
    "al_L": (16.5, 1.0),
    "al_R": (-16.5, 3.0),
    "cphs_L": (3.5, -11.0),
    "cphs_R": (-3.5, -11.0),
    "cphi_L": (4.0, -15.5),
    "cphi_R": (-4.0, -15.5),
    "ch_L": (18.0, -19.0),
    "ch_R": (-20.0, -17.5),
    "cheek_L": (30.0, 2.0),
    "cheek_R": (-30.0, 2.0),
    # extra points
    "brow_in_L": (12.0, 47.0),
    "brow_in_R": (-12.0, 47.0),
    "brow_mid_L": (22.0, 48.0),
    "brow_mid_R": (-22.0, 48.0),
    "brow_out_L": (31.0, 46.0),
    "brow_out_R": (-31.0, 46.0),
    "forehead": (0.0, 62.0),
    "forehead_L": (18.0, 60.0),
    "forehead_R": (-18.0, 60.0),
    "nose_bridge": (0.0, 25.0),
    "cheek_up_L": (26.0, 18.0),
    "cheek_up_R": (-26.0, 18.0),
    "cheek_low_L": (26.0, -8.0),
    "cheek_low_R": (-27.0, -10.0),
    "lip_lower": (-3.0, -21.5),
    "lip_lower_L": (9.0, -22.0),
    "lip_lower_R": (-9.0, -21.0),
    "chin": (6.0, -33.0),
    "chin_L": (16.0, -30.0),
    "chin_R": (-18.0, -28.0),
}


@dataclass(frozen=True)
class MarkerSet:
    """Markers bound to a mesh: ``names`` (K,), ``face`` (K,) triangle ids, ``bary`` (K, 3)."""

    names: tuple[str, ...]
    face: np.ndarray
    bary: np.ndarray

    def positions(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Marker positions (K, 3) m (or (T, K, 3) for ``vertices`` (T, N, 3))."""
        tri = vertices[..., faces[self.face], :]  # (..., K, 3, 3)
        return np.einsum("kj,...kjc->...kc", self.bary, tri)


def cast_along_z(vertices: np.ndarray, faces: np.ndarray, xy: np.ndarray) -> tuple[int, np.ndarray]:
    """Frontmost (largest z) surface hit of the line through ``xy`` (2,) m parallel to z.

    Returns ``(triangle id, barycentric weights (3,))``; raises ValueError on a miss.
    """
    near = np.nonzero((np.abs(vertices[:, :2] - xy) < 0.01).all(axis=1))[0]  # 1 cm box
    cand = np.nonzero(np.isin(faces, near).any(axis=1))[0]
    tri = vertices[faces[cand]][:, :, :2]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    keep = ((lo <= xy) & (xy <= hi)).all(axis=1)
    cand, tri = cand[keep], tri[keep]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    m = np.stack([b - a, c - a], axis=2)  # (C, 2, 2)
    det = np.linalg.det(m)
    ok = np.abs(det) > 0
    uv = np.zeros((len(cand), 2))
    uv[ok] = np.linalg.solve(m[ok], (xy - a[ok])[..., None])[..., 0]
    bary = np.column_stack([1.0 - uv.sum(axis=1), uv])
    inside = ok & (bary >= -1e-12).all(axis=1)
    if not inside.any():
        raise ValueError(f"no surface under actor-frame (x, y) = {xy} m (scan hole?)")
    z = np.einsum("cj,cj->c", bary, vertices[faces[cand], 2])
    best = np.nonzero(inside)[0][np.argmax(z[inside])]
    return int(cand[best]), bary[best]


def place_markers(
    vertices: np.ndarray, faces: np.ndarray, xy_mm: dict[str, tuple[float, float]] | None = None
) -> MarkerSet:
    """Bind markers (default ``MARKER_XY_MM``) to the neutral actor mesh (N, 3) m / (M, 3)."""
    xy_mm = MARKER_XY_MM if xy_mm is None else xy_mm
    hits = []
    for name, xy in xy_mm.items():
        try:
            hits.append(cast_along_z(vertices, faces, np.asarray(xy) * 1e-3))
        except ValueError as exc:
            raise ValueError(f"marker {name!r}: {exc}; move it in MARKER_XY_MM") from exc
    return MarkerSet(
        names=tuple(xy_mm),
        face=np.array([h[0] for h in hits], dtype=np.int64),
        bary=np.array([h[1] for h in hits]),
    )
