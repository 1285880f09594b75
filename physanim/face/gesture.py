"""Exaggeration gestures over time: how active the face model's action units are per frame,
so that a gesture acts where its expression does (``simulate.drive.actuation_scale_with``).

The fitted actuation of a region moves the skin for every expression that region takes part
in: the mouth's both opens the jaw drop and pulls the smile. Scaled in every frame, "smile
x1.5" also drove the jaw drop's lower lip 1.5 times as hard (233 tets turned inside out on the
demo, the mouth half closed); scaled by the smile's own activity, it exaggerates the smile.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray


def unit_activity(
    au: NDArray, au_names: Sequence[str], units: Sequence[str], full_span: float
) -> NDArray:
    """(T,) in [0, 1]: per frame, the largest activity of the action ``units`` among the fit's
    ``au`` (T, n_au) named ``au_names``, each unit's curve scaled from its least (0) to its
    largest (1) value over the run, or over ``full_span`` (action units) where it varies less
    (a unit that does not vary is 0 throughout), to the fourth power: a soft gate that keeps
    the peak and leaves at a hundredth the fit's leak of a unit into other expressions (the
    demo's lip corner pullers stand at 0.2-0.33 of their peak in the jaw drop; unsquared,
    "smile x1.5" still turned 32 tets there, squared 15 with 14 held; on the capture of
    2026-12-07, squared 155 with 128 held, to the fourth 128, the mouth corners' peaks the
    same). The ``full_span`` keeps a performance without the expression from reading the
    leak as its peak: over the library the lip corner pullers' leak spans at most 0.19
    (jaw_side, whose jaw drop "smile x1.5" scaled by 1.18 and turned 26 tets there), a smile
    0.40-1.03. ValueError names the units the fit does not have."""
    names = list(au_names)
    unknown = [u for u in units if u not in names]
    if unknown:
        raise ValueError(
            f"simulate.drive.actuation_scale_with: {unknown} are not action units of the fit "
            f"(it has {names})"
        )
    au = np.asarray(au, dtype=np.float64)
    curves = au[:, [names.index(u) for u in units]]
    low, span = curves.min(axis=0), np.ptp(curves, axis=0)
    scaled = np.where(span > 1e-9, (curves - low) / np.maximum(span, full_span), 0.0)
    return scaled.max(axis=1, initial=0.0) ** 4


def gesture_factors(factors: NDArray, activity: NDArray | None) -> NDArray:
    """The gesture's factor of each patch: ``factors`` (P,) in every frame when ``activity``
    is None, else (T, P) ``1 + (factors - 1) * activity`` (T,): the full factor where the
    expression peaks, none where it rests."""
    factors = np.asarray(factors, dtype=np.float64)
    if activity is None:
        return factors
    return 1.0 + (factors[None, :] - 1.0) * np.asarray(activity, dtype=np.float64)[:, None]
