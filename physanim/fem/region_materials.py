"""Per-tet material constants from region labels and a materials file (:class:`MaterialModel`).

The bridge from the mesh layer's regions to the FEM's :class:`TetMaterials`.
"""

from __future__ import annotations

import numpy as np

from physanim.fem.materials import TetMaterials
from physanim.mesh.params import REGION_NAMES, MaterialModel


def material_table(model: MaterialModel) -> np.ndarray:
    """(1 + len(REGION_NAMES), 4) rows [E Pa, nu, eta Pa*s, rho kg/m^3] per region label
    (row 0 default; regions absent from the file take the default values)."""
    rows = []
    for name in ("default", *REGION_NAMES):
        m = model.regions.get(name, model.default)
        rows.append([m.E_kPa * 1e3, m.nu, m.eta_Pa_s, m.rho_kg_m3])
    return np.asarray(rows)


def extra_table(model: MaterialModel) -> dict[str, np.ndarray]:
    """The law-declared fields beyond E, nu, eta, rho: name -> (1 + len(REGION_NAMES),) SI
    values per region label (row 0 default). A region that omits a field takes the default's
    value; a field no default gives is an error naming the region."""
    default = model.default.fields
    for region, values in model.regions.items():
        unknown = sorted(set(values.fields) - set(default))
        if unknown:
            raise ValueError(
                f"materials file '{model.name}': region {region} gives fields {unknown}, which "
                "the default section lacks; give them under default.fields too"
            )
    regions = [model.regions.get(n, model.default) for n in REGION_NAMES]
    return {
        field: np.array([value, *(r.fields.get(field, value) for r in regions)])
        for field, value in default.items()
    }


def tet_materials(tet_labels: np.ndarray, model: MaterialModel) -> TetMaterials:
    """Constants (m,) per tet from region labels (m,) (0 default, i+1 = REGION_NAMES[i])."""
    labels = np.asarray(tet_labels, dtype=np.int64)
    table = material_table(model)
    if labels.size and (labels.min() < 0 or labels.max() >= len(table)):
        raise ValueError(
            f"tet_labels must lie in [0, {len(table)}), got [{labels.min()}, {labels.max()}]"
        )
    values = table[labels]
    extra = {name: column[labels] for name, column in extra_table(model).items()}
    return TetMaterials(
        E=values[:, 0], nu=values[:, 1], eta=values[:, 2], rho=values[:, 3], extra=extra
    )
