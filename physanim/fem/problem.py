"""A driven FEM problem: the tet mesh, its per-tet materials and its boundary conditions.

What ``simulate`` solves and what a reduced preview projects: one typed value instead of a
bag of arguments, so the face drive builds it once and every solver reads the same fields.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from physanim.fem.boundary import BoundaryConditions, SpringDrive
from physanim.fem.materials import TetMaterials


@dataclass(frozen=True)
class FemProblem:
    """``nodes`` (N, 3) m at rest, ``tets`` (M, 4) positively oriented node ids,
    ``materials`` per tet, ``conditions`` (driven, fixed and spring-pulled nodes with their
    motion at the capture frame times, ``conditions.frame_dt`` s apart). Build with
    :meth:`driven`, which validates the conditions against the mesh."""

    nodes: np.ndarray
    tets: np.ndarray
    materials: TetMaterials
    conditions: BoundaryConditions

    @classmethod
    def driven(
        cls,
        nodes: np.ndarray,
        tets: np.ndarray,
        materials: TetMaterials,
        driven_idx: np.ndarray,
        driven_traj: np.ndarray,
        frame_dt: float,
        fixed_idx: np.ndarray | None = None,
        springs: SpringDrive | None = None,
    ) -> FemProblem:
        """The problem with ``driven_idx`` (n_d,) following ``driven_traj`` (T, n_d, 3) m,
        ``fixed_idx`` held, optional ``springs``; ValueError names a bad argument."""
        conditions = BoundaryConditions.checked(
            len(nodes), driven_idx, driven_traj, frame_dt, fixed_idx, springs
        )
        return cls(np.asarray(nodes, dtype=np.float64), np.asarray(tets), materials, conditions)

    @property
    def frame_dt(self) -> float:
        """Time between capture frames, s."""
        return self.conditions.frame_dt

    @property
    def n_frames(self) -> int:
        """Capture frames T the conditions give."""
        return self.conditions.n_frames

    def with_materials(self, materials: TetMaterials) -> FemProblem:
        """The same mesh and conditions with other materials (a material edit)."""
        return dataclasses.replace(self, materials=materials)
