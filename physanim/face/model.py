"""The project's CANDIDE-style face model: a low-poly wireframe with Shape and Action Units.

The model lives in the actor frame (``physanim.face.landmarks``: metres, +x actor's left,
+y up, +z out of the face, origin at the neutral pronasale). Its geometry is

    X(su, au) = X0 + sum_i su_i S_i + sum_j au_j A_j          (V, 3) metres
    shape(su, au, pose) = X(su, au) @ R(pose[:3]).T + pose[3:]

with ``S`` (n_su, V, 3) Shape-Unit and ``A`` (n_au, V, 3) Action-Unit displacement fields in
metres per unit. Action Units are FACS-named and scaled so 0 = neutral, 1 = full activation;
Shape Units are scaled so +-1 is a moderate identity change (each field's docstring in
``build_model`` says by how much). ``pose`` is ``(6,)``: a rotation vector (rad) and a
translation (m).

File format (``physanim/face/data/model.npz``, written by ``physanim.face.build_model``):
``vertices`` (V, 3) float64 m; ``triangles`` (F, 3) int64 (counter-clockwise seen from +z);
``vertex_names`` (V,) str (every vertex is named; all ``FEATURE_POINTS`` are among them);
``mirror`` (V,) int64 index of each vertex's bilateral twin (itself on the midline);
``layout`` (V, 2) float64 m, the symmetric 2D design layout in the actor x-y plane;
``su`` (n_su, V, 3) and ``au`` (n_au, V, 3) float64 m per unit; ``su_names``, ``au_names``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

#: The packaged model file.
MODEL_PATH = Path(__file__).parent / "data" / "model.npz"

#: The lips' contact line (the mouth slit) of the model, from the right mouth corner to the
#: left: (upper lip vertex, lower lip vertex) pairs; the corners are shared.
MOUTH_SLIT: tuple[tuple[str, str], ...] = (
    ("ch_R", "ch_R"),
    ("lip_upper_in_2_R", "lip_lower_in_2_R"),
    ("lip_upper_in_1_R", "lip_lower_in_1_R"),
    ("stomion_superius", "stomion_inferius"),
    ("lip_upper_in_1_L", "lip_lower_in_1_L"),
    ("lip_upper_in_2_L", "lip_lower_in_2_L"),
    ("ch_L", "ch_L"),
)


def mouth_line_points(vertices: np.ndarray, vertex_names: list[str]) -> np.ndarray | None:
    """Lip contact polyline (P, 3) m, right to left corner: midpoints of the MOUTH_SLIT pairs
    of a posed model ``vertices`` (V, 3) m; None when the model lacks those vertices."""
    index = {n: i for i, n in enumerate(vertex_names)}
    if any(u not in index or lo not in index for u, lo in MOUTH_SLIT):
        return None
    v = np.asarray(vertices, dtype=np.float64)
    return np.stack([0.5 * (v[index[u]] + v[index[lo]]) for u, lo in MOUTH_SLIT])


def pose_matrix(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (3, 3) and translation (3,) m of a pose ``(6,)`` = (rotation vector rad, t m)."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (6,):
        raise ValueError(
            f"pose: expected shape (6,) = (rotvec rad, translation m), got {pose.shape}"
        )
    return Rotation.from_rotvec(pose[:3]).as_matrix(), pose[3:]


@dataclass(frozen=True)
class FaceModel:
    """A parametrised face wireframe (see the module docstring for units and shapes)."""

    vertices: np.ndarray
    triangles: np.ndarray
    vertex_names: tuple[str, ...]
    mirror: np.ndarray
    layout: np.ndarray
    su: np.ndarray
    au: np.ndarray
    su_names: tuple[str, ...]
    au_names: tuple[str, ...]
    names: dict[str, int] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", {n: i for i, n in enumerate(self.vertex_names)})

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    def index(self, names: list[str] | tuple[str, ...]) -> np.ndarray:
        """Vertex indices (K,) of the named vertices; ValueError names any unknown name."""
        unknown = [n for n in names if n not in self.names]
        if unknown:
            raise ValueError(
                f"face model has no vertex named {unknown}; known: {self.vertex_names}"
            )
        return np.array([self.names[n] for n in names], dtype=np.int64)

    def deform(self, su: np.ndarray | None = None, au: np.ndarray | None = None) -> np.ndarray:
        """Model-frame vertices (V, 3) m for Shape Units ``su`` (n_su,) and AUs ``au`` (n_au,)."""
        out = self.vertices.copy()
        for coeffs, basis, what in ((su, self.su, "su"), (au, self.au, "au")):
            if coeffs is None:
                continue
            coeffs = np.asarray(coeffs, dtype=np.float64)
            if coeffs.shape != (len(basis),):
                raise ValueError(f"{what}: expected shape ({len(basis)},), got {coeffs.shape}")
            out += np.tensordot(coeffs, basis, axes=1)
        return out

    def shape(
        self,
        su: np.ndarray | None = None,
        au: np.ndarray | None = None,
        pose: np.ndarray | None = None,
    ) -> np.ndarray:
        """Posed vertices (V, 3) m: ``deform(su, au)`` rotated and translated by ``pose`` (6,)."""
        out = self.deform(su, au)
        if pose is None:
            return out
        rot, t = pose_matrix(pose)
        return out @ rot.T + t


def save_face_model(model: FaceModel, path: Path) -> None:
    """Write ``model`` to an ``.npz`` file in the format of the module docstring."""
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        vertices=model.vertices,
        triangles=model.triangles,
        vertex_names=np.array(model.vertex_names),
        mirror=model.mirror,
        layout=model.layout,
        su=model.su,
        au=model.au,
        su_names=np.array(model.su_names),
        au_names=np.array(model.au_names),
    )


@cache
def _load(path: Path) -> FaceModel:
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: face model file missing; rebuild it: python -m physanim.face.build_model"
        )
    with np.load(path) as d:
        return FaceModel(
            vertices=d["vertices"].astype(np.float64),
            triangles=d["triangles"].astype(np.int64),
            vertex_names=tuple(str(n) for n in d["vertex_names"]),
            mirror=d["mirror"].astype(np.int64),
            layout=d["layout"].astype(np.float64),
            su=d["su"].astype(np.float64),
            au=d["au"].astype(np.float64),
            su_names=tuple(str(n) for n in d["su_names"]),
            au_names=tuple(str(n) for n in d["au_names"]),
        )


def load_face_model(path: Path | str | None = None) -> FaceModel:
    """Load the packaged face model (or the ``.npz`` at ``path``); cached, treat as read-only."""
    return _load(Path(path) if path is not None else MODEL_PATH)
