"""Per-run measures of a face animation: landmark curves, peaks, driven/free lag, truth errors."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from physanim.evaluate.symmetry import displacement_curves, lag_frames, symmetry_cost
from physanim.mesh.binding import BINDERS


@dataclass(frozen=True)
class LandmarkMeasures:
    """Measures of landmark trajectories (T, K, 3) m.

    ``cost`` (T,) symmetry cost (natural log), ``e_left``/``e_right`` (T,); ``displacement``
    (T, K) m from frame 0; ``peak`` (K,) m and ``peak_frame`` (K,) of each landmark.
    """

    cost: NDArray
    e_left: NDArray
    e_right: NDArray
    displacement: NDArray
    peak: NDArray
    peak_frame: NDArray


def landmark_measures(points: NDArray, names: Sequence[str]) -> LandmarkMeasures:
    """Symmetry cost and displacement curves of named landmark trajectories (T, K, 3) m.
    A landmark the tracker lost in some frames (NaN there: a marker the lips hid) peaks over
    the frames it was tracked in; one never tracked peaks at NaN, frame 0."""
    cost, e_l, e_r = symmetry_cost(points, names)
    disp = displacement_curves(points)
    tracked = np.isfinite(disp)
    frame = np.where(tracked, disp, -np.inf).argmax(axis=0)
    peak = np.where(tracked.any(axis=0), np.take_along_axis(disp, frame[None], 0)[0], np.nan)
    return LandmarkMeasures(cost, e_l, e_r, disp, peak, frame)


def driven_free_lag(displacements: NDArray, driven: NDArray, free: NDArray, max_lag: int) -> float:
    """Frames (fractional) by which free nodes' mean displacement trails the driven nodes'
    (T, n, 3) m."""
    mag = np.linalg.norm(displacements, axis=-1)
    return lag_frames(mag[:, driven].mean(axis=1), mag[:, free].mean(axis=1), max_lag)


def region_lags(
    model: NDArray,
    reference: NDArray,
    labels: NDArray,
    names: Sequence[str],
    max_lag: int,
    min_motion_m: float,
) -> dict[str, float | None]:
    """Lag (frames, fractional; > 0 when the model trails) of the ``model``'s motion behind
    the ``reference``'s, both (T, N, 3) m displacements of the same N points, overall and per
    region (``labels`` (N,) indices into ``names``): of each set's mean displacement magnitude
    per frame (:func:`~physanim.evaluate.symmetry.lag_frames`). None where the reference
    curve's range stays below a quarter of ``min_motion_m`` (a region that does not move has
    no timing; a region's mean moves less than its moving points)."""
    mag_model = np.linalg.norm(model, axis=-1)
    mag_ref = np.linalg.norm(reference, axis=-1)
    sets = {"overall": np.ones(len(labels), dtype=bool)}
    sets |= {name: labels == i for i, name in enumerate(names)}
    out: dict[str, float | None] = {}
    for name, members in sets.items():
        if not members.any():
            out[name] = None
            continue
        ref, follower = mag_ref[:, members].mean(axis=1), mag_model[:, members].mean(axis=1)
        moves = ref.max() - ref.min() >= 0.25 * min_motion_m
        out[name] = lag_frames(ref, follower, max_lag) if moves else None
    return out


def surface_errors(
    point_sets: Sequence[NDArray],
    truth_vertices: NDArray,
    truth_faces: NDArray,
    frames: Sequence[int],
    search: str = "bvh",
) -> list[NDArray]:
    """RMS distance (len(frames),) m of each point set (T, N_i, 3) to the true surface (T, V, 3)
    per frame; one exact closest-point search per frame serves all the sets (``search``: which,
    ``physanim.mesh.binding.BINDERS``)."""
    bind = BINDERS[search]
    sizes = np.cumsum([p.shape[1] for p in point_sets])[:-1]
    out: list[list[float]] = [[] for _ in point_sets]
    for t in frames:
        points = np.concatenate([p[t] for p in point_sets])
        d = bind(points, truth_vertices[t], truth_faces).distance
        for rms, part in zip(out, np.split(d, sizes), strict=True):
            rms.append(float(np.sqrt(np.mean(part**2))))
    return [np.asarray(rms) for rms in out]
