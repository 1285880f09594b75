"""Constitutive laws of the tet FEM: per-tet Voigt matrices from :class:`TetMaterials`.

A law is a pydantic model, so it is its own config schema: its fields are the law's settings
(``simulate.law`` in a config: ``{name: kelvin_voigt, viscosity_form: isotropic}``), its
``tet_fields`` the per-tet material fields it reads (the four base fields E, nu, eta, rho, or
any further field a materials file gives per region under ``fields``, named with its SI unit,
e.g. ``beta_s``). It has two methods: ``moduli`` (the isotropic linear elastic part, shear and
bulk modulus per tet) and ``viscosity`` (the viscous Voigt matrix C' per tet, stress = C'
strain rate). The
element formulation (:mod:`physanim.fem.elements`) decides how the volumetric part is
assembled. An active stress (muscle-like actuation, :mod:`physanim.fem.actuation`) adds to
the law's: total stress = elastic + viscous + active.

A new law is one subclass with a ``name`` literal, decorated with :func:`register_law`; a config
then selects it by that name, and ``build_model`` uses it. Voigt strain order (xx, yy, zz,
yz, xz, xy), engineering shear strains.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar, Literal, TypeVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from physanim.fem.assembly import deviatoric_matrix, lame
from physanim.fem.materials import BASE_FIELDS, TetMaterials

L = TypeVar("L", bound="MaterialLaw")

#: law name -> class, filled by :func:`register_law`
LAWS: dict[str, type[MaterialLaw]] = {}


class MaterialLaw(BaseModel, ABC):
    """Linear viscoelastic law: isotropic elasticity plus a viscous stress C' strain rate.

    Subclasses declare ``name: Literal["..."] = "..."``, their settings as pydantic fields
    (units in the descriptions) and, when they read per-tet fields beyond the base four,
    ``tet_fields``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    #: per-tet material fields the law reads (SI units; the materials file's region tables
    #: must give every field beyond E, nu, eta, rho)
    tet_fields: ClassVar[tuple[str, ...]] = BASE_FIELDS

    @abstractmethod
    def moduli(self, mat: TetMaterials) -> tuple[np.ndarray, np.ndarray]:
        """Shear modulus mu (M,) and bulk modulus kappa (M,), Pa."""

    @abstractmethod
    def viscosity(self, mat: TetMaterials) -> np.ndarray:
        """Viscous Voigt matrices C' (M, 6, 6), Pa s."""


def register_law(cls: type[L]) -> type[L]:
    """Class decorator: make ``cls`` selectable from a config by its ``name`` default."""
    name = cls.model_fields["name"].default
    if not isinstance(name, str) or not name:
        raise TypeError(f"law {cls.__name__}: declare name: Literal['...'] = '...'")
    if LAWS.get(name, cls) is not cls:
        raise ValueError(f"law name {name!r} is taken by {LAWS[name].__name__}")
    LAWS[name] = cls
    return cls


def law_from_config(value: Any) -> MaterialLaw:
    """The law a config's ``simulate.law`` names: a mapping ``{name: ..., <settings>}``
    validated against that law's schema, or a law instance as is. ValueError names the
    registered laws or the failing setting."""
    if isinstance(value, MaterialLaw):
        return value
    if not isinstance(value, Mapping) or "name" not in value:
        raise ValueError(f"law must be a mapping with a 'name' among {sorted(LAWS)}")
    cls = LAWS.get(str(value["name"]))
    if cls is None:
        raise ValueError(f"unknown law {value['name']!r}; registered laws: {sorted(LAWS)}")
    try:
        return cls.model_validate(dict(value))
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(map(str, e['loc'])) or 'law'}: {e['msg']}" for e in exc.errors()
        )
        raise ValueError(f"law {cls.model_fields['name'].default!r}: {problems}") from None


@register_law
class KelvinVoigt(MaterialLaw):
    """Kelvin-Voigt: sigma = C eps + C' eps_dot with C from (E, nu) and a deviatoric C' from
    the shear viscosity eta."""

    name: Literal["kelvin_voigt"] = "kelvin_voigt"
    viscosity_form: Literal["isotropic", "seed"] = Field(
        "isotropic",
        description="Kelvin-Voigt viscosity matrix C' (Pa s): 'isotropic' = 2 eta dev(strain "
        "rate), rotation invariant; 'seed' = SPEC eq 4.26 literally, whose normal block is half "
        "the isotropic one (same shear viscosity eta)",
    )

    def moduli(self, mat: TetMaterials) -> tuple[np.ndarray, np.ndarray]:
        return lame(mat.E, mat.nu)

    def viscosity(self, mat: TetMaterials) -> np.ndarray:
        return deviatoric_matrix(mat.eta, 2.0 if self.viscosity_form == "isotropic" else 1.0)
