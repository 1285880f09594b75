"""Constitutive laws of the tet FEM: per-tet Voigt matrices from :class:`TetMaterials`.

A law is a small object with two methods: ``moduli`` (the isotropic linear elastic part,
shear and bulk modulus per tet) and ``viscosity`` (the viscous Voigt matrix C' per tet,
stress = C' strain rate). The element formulation (:mod:`physanim.fem.elements`) decides how
the volumetric part is assembled. A new law is a subclass passed to
``build_model(..., law=MyLaw())``; nothing else changes. Voigt strain order
(xx, yy, zz, yz, xz, xy), engineering shear strains.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Literal

import numpy as np

from physanim.fem.assembly import deviatoric_matrix, lame
from physanim.fem.materials import TetMaterials


class MaterialLaw(ABC):
    """Linear viscoelastic law: isotropic elasticity plus a viscous stress C' strain rate."""

    @abstractmethod
    def moduli(self, mat: TetMaterials) -> tuple[np.ndarray, np.ndarray]:
        """Shear modulus mu (M,) and bulk modulus kappa (M,), Pa."""

    @abstractmethod
    def viscosity(self, mat: TetMaterials) -> np.ndarray:
        """Viscous Voigt matrices C' (M, 6, 6), Pa s."""


@dataclass(frozen=True)
class KelvinVoigt(MaterialLaw):
    """Kelvin-Voigt: sigma = C eps + C' eps_dot with C from (E, nu) and a deviatoric C' from
    the shear viscosity eta. ``viscosity``: 'isotropic' = 2 eta dev(strain rate), rotation
    invariant; 'seed' = SPEC eq 4.26 literally (normal block half the isotropic one)."""

    form: Literal["isotropic", "seed"] = "isotropic"

    def moduli(self, mat: TetMaterials) -> tuple[np.ndarray, np.ndarray]:
        return lame(mat.E, mat.nu)

    def viscosity(self, mat: TetMaterials) -> np.ndarray:
        return deviatoric_matrix(mat.eta, 2.0 if self.form == "isotropic" else 1.0)
