"""Kinematics of the FEM run: linear (small displacements) or corotational (large rotations).

Each gives the Newmark integrator of the run and, per frame, the element displacements that
the strain and stress are computed from and the elastic energy.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from physanim.fem.corotational import (
    CorotationalNewmark,
    local_displacements,
    rotations,
    strain_energy,
)
from physanim.fem.model import FemModel
from physanim.fem.newmark import Newmark
from physanim.fem.parallel_spmv import ParallelCSR, SymmetricQuadraticForm
from physanim.fem.params import SimulateParams

Split = tuple[sp.csr_matrix, sp.csr_matrix, np.ndarray] | None


class Kinematics(Protocol):
    """``adaptive``: may run with adaptive stepping; ``springs``: supports spring drives."""

    adaptive: bool
    springs: bool

    def integrator(
        self, stiffness: sp.csr_matrix, split: Split, dt: float, prescribed: np.ndarray
    ) -> Newmark:
        """Newmark integrator at step ``dt`` s with ``prescribed`` (n_c,) DOFs."""

    def element_displacements(self, d: np.ndarray) -> np.ndarray:
        """Element displacements (M, 12) m that strain the tets, from d (3N,) m."""

    def strain_energy(self, d: np.ndarray, u_elem: np.ndarray) -> float:
        """Elastic energy, J, of d (3N,) with its element displacements u_elem (M, 12)."""


class Linear:
    """Small-displacement kinematics: u_e = d[dofs], energy d^T K d / 2."""

    adaptive = True
    springs = True

    def __init__(self, model: FemModel, params: SimulateParams) -> None:
        self.model, self.params = model, params
        # d^T K d = d^T K_el d + (G d)^T diag(w) (G d): K_el's one ring, not K's two
        self._strain = SymmetricQuadraticForm(model.K_el)
        self._volumetric = None if model.G is None else ParallelCSR(model.G)

    def integrator(
        self, stiffness: sp.csr_matrix, split: Split, dt: float, prescribed: np.ndarray
    ) -> Newmark:
        p, m = self.params, self.model
        return Newmark(stiffness, m.M, m.C, dt, prescribed, p.solver, split, p.precision)

    def element_displacements(self, d: np.ndarray) -> np.ndarray:
        out = np.empty(self.model.dofs.shape)
        _gather(np.ascontiguousarray(d, np.float64), self.model.dofs, out)
        return out

    def strain_energy(self, d: np.ndarray, u_elem: np.ndarray) -> float:
        energy = self._strain(d)
        if self._volumetric is not None:
            energy += float(self.model.w_vol @ (self._volumetric @ d) ** 2)
        return 0.5 * energy


class Corotational:
    """Corotational kinematics: each tet strained by its displacement in its rotated frame."""

    adaptive = False
    springs = False

    def __init__(self, model: FemModel, params: SimulateParams) -> None:
        self.model, self.params = model, params

    def integrator(
        self, stiffness: sp.csr_matrix, split: Split, dt: float, prescribed: np.ndarray
    ) -> Newmark:
        p = self.params
        return CorotationalNewmark(
            self.model, dt, prescribed, p.solver, p.corot_rtol, p.corot_max_iter
        )

    def element_displacements(self, d: np.ndarray) -> np.ndarray:
        return local_displacements(self.model, d, rotations(self.model, d))

    def strain_energy(self, d: np.ndarray, u_elem: np.ndarray) -> float:
        return strain_energy(self.model, u_elem)


def kinematics(model: FemModel, params: SimulateParams) -> Kinematics:
    """The kinematics ``params.corotational`` asks for."""
    return (Corotational if params.corotational else Linear)(model, params)


# d[dofs] on numba's threads, once per output frame: numpy's gather took 3.4 ms on a 2 mm demo
# mesh (150k tets)
@njit(cache=True, parallel=True)
def _gather(d, dofs, out):
    """out (M, 12) = d[dofs] for element DOFs dofs (M, 12)."""
    for e in prange(dofs.shape[0]):
        for j in range(dofs.shape[1]):
            out[e, j] = d[dofs[e, j]]
