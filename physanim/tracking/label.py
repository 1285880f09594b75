"""Label detected dots with marker identities by fitting the 2D marker template."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from physanim.transforms import Transform, fit_transform

_BIG = 1e6


def assign(predicted: np.ndarray, detections: np.ndarray, gate: float) -> np.ndarray:
    """Optimal one-to-one assignment of predictions (K, 2) to detections (N, 2), px.

    Returns (K,) int64 detection index per prediction, -1 where none lies within ``gate``
    px (NaN predictions are never assigned). Minimises the summed squared distance.
    """
    out = np.full(len(predicted), -1, dtype=np.int64)
    ok = np.isfinite(predicted).all(axis=1)
    if not ok.any() or len(detections) == 0:
        return out
    d2 = ((predicted[ok, None, :] - detections[None, :, :]) ** 2).sum(axis=2)
    cost = np.where(d2 <= gate**2, d2, _BIG)
    r, c = linear_sum_assignment(cost)
    good = cost[r, c] < _BIG
    out[np.nonzero(ok)[0][r[good]]] = c[good]
    return out


def label_markers(
    template: np.ndarray,
    detections: np.ndarray,
    gate: float,
    *,
    angles_deg: tuple[float, ...] = (-30.0, -15.0, 0.0, 15.0, 30.0),
    iterations: int = 20,
) -> tuple[np.ndarray, Transform]:
    """Match a 2D marker template (K, 2) to detected dots (N, 2) in px.

    Robust similarity fit with unknown correspondences: from a moment-matched start at each
    of ``angles_deg``, alternate optimal assignment (``assign``, gate shrinking to ``gate``
    px) and a similarity fit on the matched pairs whose residual is below 3x their median
    (outlier rejection); keep the start that matches most dots with the least error.
    Returns ((K,) detection index per template marker or -1, the template->image transform).
    """
    if len(detections) < 3:
        raise ValueError(f"detections: need at least 3 dots to label, found {len(detections)}")
    t_c, d_c = template.mean(axis=0), detections.mean(axis=0)
    scale = np.sqrt(((detections - d_c) ** 2).sum(1).mean() / ((template - t_c) ** 2).sum(1).mean())
    best: tuple[float, np.ndarray, Transform] | None = None
    for ang in np.radians(angles_deg):
        rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        tr = Transform(scale, rot, d_c - scale * rot @ t_c)
        for it in range(iterations):
            g = max(gate, 8.0 * gate * (1.0 - it / max(iterations // 2, 1)))
            match = assign(tr.apply(template), detections, g)
            m = match >= 0
            if m.sum() < 3:
                break
            res = np.linalg.norm(tr.apply(template[m]) - detections[match[m]], axis=1)
            inl = res <= 3.0 * np.median(res) + 1e-9
            idx = np.nonzero(m)[0][inl]
            tr = fit_transform(template[idx], detections[match[idx]])
        match = assign(tr.apply(template), detections, gate)
        m = match >= 0
        if m.sum() < 3:
            continue
        err = np.linalg.norm(tr.apply(template[m]) - detections[match[m]], axis=1).mean()
        score = m.sum() - err / gate
        if best is None or score > best[0]:
            best = (score, match, tr)
    if best is None:
        raise ValueError("cannot fit the marker template to the detected dots; check the template")
    return best[1], best[2]
