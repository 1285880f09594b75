"""Marker templates: the names and neutral 3D positions (actor frame, m) of painted markers.

Formats: a JSON file ``{"names": [...], "positions_m": [[x, y, z], ...]}``, or a Zarr group
holding ``markers_neutral`` (K, 3) with attribute ``marker_names`` (the demo's
``ground_truth.zarr``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import zarr


def load_marker_template(path: Path) -> tuple[list[str], np.ndarray]:
    """(names (K,), positions (K, 3) m) from a template file; clear errors otherwise."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(
            f"{path}: marker template not found; for a recording without painted markers set "
            "track.backend=markerless, else give track.template as a JSON file "
            '{"names": [...], "positions_m": [[x, y, z], ...]} or a Zarr group with '
            "markers_neutral + marker_names"
        )
    if path.suffix == ".json":
        data = json.loads(path.read_text())
        names, pos = data.get("names"), np.asarray(data.get("positions_m", []), float)
    else:
        group = zarr.open_group(path, mode="r")
        if "markers_neutral" not in group or "marker_names" not in group.attrs:
            raise ValueError(f"{path}: needs array markers_neutral and attribute marker_names")
        names, pos = list(group.attrs["marker_names"]), np.asarray(group["markers_neutral"][...])
    if not names or pos.shape != (len(names), 3):
        raise ValueError(
            f"{path}: expected K names and (K, 3) positions, got {len(names or [])} names and "
            f"positions of shape {pos.shape}"
        )
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: marker names must be unique")
    return list(names), pos
