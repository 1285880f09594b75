"""A driven FEM problem: the tet mesh, its per-tet materials, its boundary conditions and an
optional actuation (active stress, :mod:`physanim.fem.actuation`).

What ``simulate`` solves and what a reduced preview projects: one typed value instead of a
bag of arguments, so the face drive builds it once and every solver reads the same fields.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from physanim.fem.actuation import Actuation
from physanim.fem.boundary import BoundaryConditions, FrameForce, SpringDrive
from physanim.fem.materials import TetMaterials
from physanim.fem.model import FemModel


@dataclass(frozen=True)
class FemProblem:
    """``nodes`` (N, 3) m at rest, ``tets`` (M, 4) positively oriented node ids,
    ``materials`` per tet, ``conditions`` (driven, fixed and spring-pulled nodes with their
    motion at the capture frame times, ``conditions.frame_dt`` s apart), ``actuation`` the
    active stress at the same frames, or None. Build with :meth:`driven`, which validates the
    conditions against the mesh, and :meth:`with_actuation`."""

    nodes: np.ndarray
    tets: np.ndarray
    materials: TetMaterials
    conditions: BoundaryConditions
    actuation: Actuation | None = None

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

    def with_actuation(self, actuation: Actuation | None) -> FemProblem:
        """The problem driven by ``actuation`` too (its frames the conditions'; its patches
        over these tets); ValueError otherwise."""
        if actuation is not None:
            if actuation.n_frames != self.n_frames:
                raise ValueError(
                    f"actuation has {actuation.n_frames} frames, the conditions {self.n_frames}"
                )
            if actuation.basis.weights.shape[0] != len(self.tets):
                raise ValueError(
                    f"actuation basis covers {actuation.basis.weights.shape[0]} tets, the "
                    f"mesh has {len(self.tets)}"
                )
        return dataclasses.replace(self, actuation=actuation)

    def load(self, model: FemModel, free: np.ndarray) -> FrameForce | None:
        """:func:`applied_load` of this problem's conditions and actuation."""
        return applied_load(self.conditions, self.actuation, model, free)

    def drive_energy(self, model: FemModel) -> float:
        """Energy scale of the drive, J (:meth:`BoundaryConditions.drive_energy`, or the
        actuation's :meth:`~physanim.fem.actuation.Actuation.energy_scale` if larger)."""
        energy = self.conditions.drive_energy(model.stiffness_diagonal())
        if self.actuation is not None:
            energy = max(energy, self.actuation.energy_scale(model))
        return energy


def applied_load(
    conditions: BoundaryConditions,
    actuation: Actuation | None,
    model: FemModel,
    free: np.ndarray,
) -> FrameForce | None:
    """The applied forces on the ``free`` (n_u,) DOFs of ``model`` (the problem's assembly):
    the springs' pulls of ``conditions`` plus the ``actuation``'s active forces; None when
    there are neither."""
    springs = conditions.spring_force(free)
    if actuation is None:
        return springs
    active = actuation.force(model, free, conditions.frame_dt)
    return active if springs is None else springs + active
