"""Motion fidelity: how well a simulated skin reproduces the true motion of the actor's skin.

Skin points of a model (a sample of scan vertices moved by the FEM or by the capture) are
bound to the actor's true neutral surface at frame 0 (closest point, barycentric weights)
and followed through the true motion, which gives each point's true displacement
``u_true(t)``.  The relative displacement error of a set of points at frame t is

    e(t) = sqrt(mean |u_model - u_true|^2) / sqrt(mean |u_true|^2)

over the points whose true motion at t exceeds ``min_motion_m`` (1 mm by default): 0 for a
model that moves exactly like the truth, 1 for a model that does not move at all.  Unlike a
point-to-surface distance, it sees sliding and a mouth that stays shut.

Only points on the true surface have a truth: a point farther than ``TRUTH_MAX_DISTANCE_M``
from it at frame 0 lies where the actor has no skin (a hole of the actor's range scan that the
model's scan has filled), and the closest true point, on the hole's rim, would lend it the
rim's motion. Such points are left out of the figures (:meth:`TrueMotion.on_truth`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from physanim.face.params import FACE_REGIONS
from physanim.mesh.binding import BINDERS
from physanim.mesh.kinematic import blend_frames, blend_matrix
from physanim.mesh.seam import LOWER, UPPER, MouthLine

#: Facial regions of the fidelity report, in order; every point gets one (or "other").
REGIONS: tuple[str, ...] = FACE_REGIONS
#: A model point farther than this from the true neutral surface has no truth, m. The demo's
#: scan vertices lie within 0.76 mm of the actor's surface away from the actor's holes (the
#: scan stage re-meshes the same range scan); 1,640 of its 24,447 lie farther, up to 8 mm, in
#: the holes the scan stage filled: a band under the nose and the chin's crack.
TRUTH_MAX_DISTANCE_M = 1e-3


@dataclass(frozen=True)
class TrueMotion:
    """True displacements (T, N, 3) m of N model points and their distance (N,) m to the truth."""

    displacement: NDArray
    distance: NDArray

    def on_truth(self, max_distance_m: float = TRUTH_MAX_DISTANCE_M) -> NDArray:
        """(N,) bool: the points within ``max_distance_m`` of the true neutral surface, the
        ones whose true motion is defined (module docstring)."""
        return self.distance <= max_distance_m


def follow_truth(
    points: NDArray, truth_vertices: NDArray, truth_faces: NDArray, search: str = "bvh"
) -> TrueMotion:
    """Bind ``points`` (N, 3) m to the true surface at frame 0 and follow it.

    ``truth_vertices`` (T, V, 3) m, head-fixed frame; ``truth_faces`` (F, 3); ``search`` the
    closest-point search (``physanim.mesh.binding.BINDERS``).
    """
    truth_vertices = np.asarray(truth_vertices, dtype=np.float64)
    bind = BINDERS[search]
    binding = bind(np.asarray(points, dtype=np.float64), truth_vertices[0], truth_faces)
    w = blend_matrix(binding, truth_faces, truth_vertices.shape[1])
    used = np.unique(w.indices)  # only the true vertices the points are bound to move them
    moved = truth_vertices[:, used] - truth_vertices[:1, used]
    return TrueMotion(blend_frames(w[:, used], moved), binding.distance)


def relative_error(u_model: NDArray, u_true: NDArray, min_motion_m: float = 1e-3) -> NDArray:
    """Relative displacement error (T,) of displacements (T, N, 3) m; NaN where no point moves.

    Only points whose true displacement at that frame exceeds ``min_motion_m`` count.
    """
    u_model = np.asarray(u_model, dtype=np.float64)
    u_true = np.asarray(u_true, dtype=np.float64)
    if u_model.shape != u_true.shape:
        raise ValueError(f"shapes differ: model {u_model.shape}, truth {u_true.shape}")
    true_sq = (u_true**2).sum(axis=-1)
    err_sq = ((u_model - u_true) ** 2).sum(axis=-1)
    moving = true_sq > min_motion_m**2
    count = moving.sum(axis=1)
    num = np.where(moving, err_sq, 0.0).sum(axis=1)
    den = np.where(moving, true_sq, 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, np.sqrt(num / np.where(den > 0, den, 1.0)), np.nan)


def face_regions(points: NDArray, landmarks: Mapping[str, NDArray]) -> NDArray:
    """Region index (N,) into REGIONS of points (N, 3) m in the actor frame (+y up); -1 = other.

    From the feature points: ``mouth`` within 12 mm of the mouth-corner segment (ch_R-ch_L)
    or between the corners down to 8 mm below it; ``jaw_chin`` below that; ``nose`` between
    the nose wings (al) from 8 mm below the pronasale up to midway to the glabella;
    ``forehead`` above the glabella minus 5 mm; ``cheeks`` everything else.
    """
    p = np.asarray(points, dtype=np.float64)
    lm = {k: np.asarray(v, dtype=np.float64) for k, v in landmarks.items()}
    ch_l, ch_r = lm["ch_L"], lm["ch_R"]
    seg = ch_l - ch_r
    s = np.clip((p - ch_r) @ seg / float(seg @ seg), 0.0, 1.0)
    to_seg = np.linalg.norm(p - (ch_r + s[:, None] * seg), axis=1)
    slope = seg[1] / seg[0]
    lip_y = ch_r[1] + slope * (p[:, 0] - ch_r[0])
    between = (p[:, 0] > ch_r[0]) & (p[:, 0] < ch_l[0])
    mouth = (to_seg < 0.012) | (between & (p[:, 1] > lip_y - 0.008) & (p[:, 1] < lip_y + 0.012))
    jaw = ~mouth & (p[:, 1] < lip_y)
    tip, glab = lm["pronasale"], lm["glabella"]
    half = 0.5 * abs(lm["al_L"][0] - lm["al_R"][0]) + 0.002
    nose = (
        ~mouth
        & (np.abs(p[:, 0] - tip[0]) < half)
        & (p[:, 1] > tip[1] - 0.008)
        & (p[:, 1] < 0.5 * (tip[1] + glab[1]))
    )
    forehead = ~mouth & ~jaw & ~nose & (p[:, 1] > glab[1] - 0.005)
    label = np.full(len(p), REGIONS.index("cheeks"), dtype=np.int8)
    for name, mask in (("forehead", forehead), ("nose", nose), ("jaw_chin", jaw)):
        label[mask] = REGIONS.index(name)
    label[mouth] = REGIONS.index("mouth")
    return label


def region_names(labels: NDArray, names: Sequence[str] = REGIONS) -> list[str | None]:
    """The region name of each index of ``labels`` (N,) into ``names`` (as
    :func:`face_regions` gives them); None for -1 (no region)."""
    return [names[r] if r >= 0 else None for r in labels]


@dataclass(frozen=True)
class Fidelity:
    """Relative displacement error per frame: ``overall`` (T,), ``regions`` (T, len(REGIONS))."""

    overall: NDArray
    regions: NDArray


def motion_fidelity(
    u_model: NDArray, u_true: NDArray, labels: NDArray, min_motion_m: float = 1e-3
) -> Fidelity:
    """Overall and per-region relative errors of displacements (T, N, 3) m; labels (N,)."""
    regions = np.stack(
        [
            relative_error(u_model[:, labels == r], u_true[:, labels == r], min_motion_m)
            for r in range(len(REGIONS))
        ],
        axis=1,
    )
    return Fidelity(relative_error(u_model, u_true, min_motion_m), regions)


def lip_gap(upper: NDArray, lower: NDArray) -> NDArray:
    """Distance (T,) m between the upper and lower lip midline points, each (T, 3) m."""
    return np.linalg.norm(np.asarray(lower) - np.asarray(upper), axis=-1)


def lip_midline_points(
    mouth: MouthLine, points: NDArray, side: NDArray, offset_m: float
) -> tuple[int, int]:
    """Indices of the upper and lower lip midline points among ``points`` (N, 3) m with lip
    ``side`` (N,): the points of that lip nearest (in x, y) to ``offset_m`` above and below
    the middle of the mouth line."""
    mid = mouth.points[len(mouth.points) // 2]
    x, y = float(mid[0]), float(mouth.height_at(np.array([mid[0]]))[0])
    out = []
    for lip, dy in ((UPPER, offset_m), (LOWER, -offset_m)):
        cand = np.nonzero(side == lip)[0]
        if len(cand) == 0:  # no seam: either side of the line
            cand = np.nonzero((points[:, 1] - y) * dy > 0)[0]
        d = np.hypot(points[cand, 0] - x, points[cand, 1] - (y + dy))
        out.append(int(cand[np.argmin(d)]))
    return out[0], out[1]
