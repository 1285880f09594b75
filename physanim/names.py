"""Positions of names in a list of names (landmarks, model vertices, regions)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def name_index(names: Sequence[str], wanted: Sequence[str]) -> np.ndarray:
    """Indices (len(wanted),) int64 of each ``wanted`` name in ``names``; KeyError naming the
    missing ones and the names there are."""
    where = {n: i for i, n in enumerate(names)}
    missing = [w for w in wanted if w not in where]
    if missing:
        raise KeyError(f"names {missing} not among {list(names)}")
    return np.array([where[w] for w in wanted], dtype=np.int64)
