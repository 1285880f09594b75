"""Ground truth of a recording (the demo's ``ground_truth.zarr``): the actor's true surface.

Layout read here: ``vertices_actor`` (T, V, 3) m, the true skin surface per frame in the
head-fixed actor frame (= the scan frame of the demo); ``faces`` (F, 3); optionally
``expression`` (T, P) with attribute ``expression_names`` (the demo's jaw_open, smile_L,
smile_R), used to find the peak frames of each expression.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zarr
from numpy.typing import NDArray


@dataclass(frozen=True)
class Truth:
    """True surface ``vertices`` (T, V, 3) m and ``faces`` (F, 3); ``expression`` (T, P) or
    None with its ``expression_names``."""

    vertices: NDArray
    faces: NDArray
    expression: NDArray | None
    expression_names: list[str]

    def peak_frames(self) -> dict[str, int]:
        """Frame of the largest value of each expression (e.g. ``jaw_open``: the jaw-drop
        peak; ``smile``: the larger of the per-side smiles), or of the largest true motion."""
        if self.expression is None:
            motion = np.linalg.norm(self.vertices - self.vertices[:1], axis=2).max(axis=1)
            return {"motion": int(np.argmax(motion))}
        return expression_peaks(self.expression, self.expression_names)


def expression_peaks(expression: NDArray, names: list[str]) -> dict[str, int]:
    """Frame of the largest value of each of the ``expression`` (T, P) curves named ``names``
    (P,); the per-side smiles (``smile_*``) share the key ``smile``."""
    out: dict[str, int] = {}
    for i, name in enumerate(names):
        key = "smile" if name.startswith("smile") else name
        frame = int(np.argmax(expression[:, i]))
        if key not in out or expression[frame, i] > expression[out[key], i]:
            out[key] = frame
    return out


def truth_peaks(path: Path, n_frames: int) -> dict[str, int]:
    """:meth:`Truth.peak_frames` of the first ``n_frames`` of the ground truth at ``path``
    (its surface read only where it has no expression curves); {} where there is none."""
    if not path.exists():
        return {}
    group = zarr.open_group(path, mode="r")
    if "expression" not in group:
        return load_truth(path, n_frames).peak_frames()
    names = list(group.attrs.get("expression_names", []))
    return expression_peaks(np.asarray(group["expression"][:n_frames]), names)


def truth_fingerprint(dataset_dir: Path, name: str) -> dict[str, object]:
    """``{"truth": ...}``: the size and modification time of every file of the ground truth
    ``dataset_dir / name``, or "none" where there is none (a stage key input: an edited or
    added truth re-runs the stages that read it)."""
    from physanim.store import files_fingerprint

    truth = dataset_dir / name
    if not truth.exists():
        return {"truth": "none"}
    files = [p for p in truth.rglob("*") if p.is_file()] if truth.is_dir() else [truth]
    return {"truth": files_fingerprint(files, dataset_dir)}


def load_truth(path: Path, n_frames: int) -> Truth:
    """The first ``n_frames`` of the ground truth at ``path``; ValueError names what is
    missing or too short."""
    group = zarr.open_group(path, mode="r")
    for name in ("vertices_actor", "faces"):
        if name not in group:
            raise ValueError(f"{path}: ground truth lacks '{name}'")
    vertices = group["vertices_actor"]
    if vertices.shape[0] < n_frames:
        raise ValueError(f"{path}: ground truth has {vertices.shape[0]} frames, the run {n_frames}")
    expression = group["expression"][:n_frames] if "expression" in group else None
    return Truth(
        vertices=np.asarray(vertices[:n_frames], dtype=np.float64),
        faces=np.asarray(group["faces"][...], dtype=np.int64),
        expression=expression,
        expression_names=list(group.attrs.get("expression_names", [])),
    )
