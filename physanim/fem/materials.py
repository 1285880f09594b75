"""Per-tetrahedron material arrays for the viscoelastic FEM."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

#: the fields every material table carries (E Pa, nu, eta Pa s, rho kg/m^3)
BASE_FIELDS: tuple[str, ...] = ("E", "nu", "eta", "rho")


@dataclass(frozen=True)
class TetMaterials:
    """Per-tet material parameters, each (M,) float64.

    E: Young's modulus, Pa. nu: Poisson's ratio. eta: shear viscosity, Pa s.
    rho: density, kg/m^3. ``extra``: further per-tet fields a material law declares
    (``MaterialLaw.tet_fields``), name (with its SI unit, e.g. ``beta_s``) -> (M,).
    """

    E: np.ndarray
    nu: np.ndarray
    eta: np.ndarray
    rho: np.ndarray
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def uniform(
        cls,
        n_tets: int,
        E: float = 192.4e3,
        nu: float = 0.495,
        eta: float = 476.8,
        rho: float = 1100.0,
        **extra: float,
    ) -> TetMaterials:
        """The same material on all tets (defaults: the seed's uniform face model)."""
        full = lambda v: np.full(n_tets, float(v))  # noqa: E731
        return cls(full(E), full(nu), full(eta), full(rho), {k: full(v) for k, v in extra.items()})

    def __getitem__(self, name: str) -> np.ndarray:
        """The per-tet field ``name`` (a base field or an extra one); KeyError lists them."""
        if name in BASE_FIELDS:
            return getattr(self, name)
        if name in self.extra:
            return self.extra[name]
        raise KeyError(f"no per-tet material field {name!r}; fields: {self.names}")

    @property
    def names(self) -> list[str]:
        """Every field this table carries, base fields first."""
        return [*BASE_FIELDS, *self.extra]

    def validated(self, n_tets: int, required: Iterable[str] = BASE_FIELDS) -> TetMaterials:
        """Return self as float64 arrays after checking shapes, physical ranges and that every
        ``required`` field (a law's ``tet_fields``) is present."""
        missing = [n for n in required if n not in self.names]
        if missing:
            raise ValueError(
                f"materials lack the per-tet field(s) {missing} the law needs; give them per "
                f"region in the materials file (fields present: {self.names})"
            )
        arrays = {}
        for name in self.names:
            a = np.broadcast_to(np.asarray(self[name], dtype=np.float64), (n_tets,))
            if not np.isfinite(a).all():
                raise ValueError(f"materials.{name} contains NaN or Inf")
            arrays[name] = a
        checks = {
            "E": (arrays["E"] > 0, "must be > 0 Pa"),
            "nu": ((arrays["nu"] > -1) & (arrays["nu"] < 0.5), "must lie in (-1, 0.5)"),
            "eta": (arrays["eta"] >= 0, "must be >= 0 Pa s"),
            "rho": (arrays["rho"] > 0, "must be > 0 kg/m^3"),
        }
        for name, (ok, rule) in checks.items():
            if not ok.all():
                i = int(np.flatnonzero(~ok)[0])
                raise ValueError(
                    f"materials.{name}[{i}] = {arrays[name][i]} {rule} "
                    f"({int((~ok).sum())} tets fail)"
                )
        base = [arrays.pop(n) for n in BASE_FIELDS]
        return TetMaterials(*base, arrays)
