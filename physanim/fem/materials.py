"""Per-tetrahedron material arrays for the viscoelastic FEM."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TetMaterials:
    """Per-tet material parameters, each (M,) float64.

    E: Young's modulus, Pa. nu: Poisson's ratio. eta: shear viscosity, Pa s.
    rho: density, kg/m^3.
    """

    E: np.ndarray
    nu: np.ndarray
    eta: np.ndarray
    rho: np.ndarray

    @classmethod
    def uniform(
        cls,
        n_tets: int,
        E: float = 192.4e3,
        nu: float = 0.495,
        eta: float = 476.8,
        rho: float = 1100.0,
    ) -> TetMaterials:
        """The same material on all tets (defaults: the seed's uniform face model)."""
        full = lambda v: np.full(n_tets, float(v))  # noqa: E731
        return cls(full(E), full(nu), full(eta), full(rho))

    def validated(self, n_tets: int) -> TetMaterials:
        """Return self as float64 arrays after checking shapes and physical ranges."""
        arrays = {}
        for name in ("E", "nu", "eta", "rho"):
            a = np.broadcast_to(np.asarray(getattr(self, name), dtype=np.float64), (n_tets,))
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
        return TetMaterials(**arrays)
