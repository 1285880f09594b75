"""Stage ``materials``: facial regions from the feature points, per-tet E, nu, eta, rho."""

from __future__ import annotations

from pydantic import ConfigDict, Field

from physanim.mesh.params import MaterialModel, MaterialsParams, TissueMaterial
from physanim.pipeline import StageContext, StageSpec

#: The seed's uniform model (SPEC section 1, item 6), used when no materials file is merged.
UNIFORM = MaterialModel(
    name="uniform",
    description="Seed 004 uniform model",
    default=TissueMaterial(E_kPa=192.4, nu=0.495, eta_Pa_s=476.8, rho_kg_m3=1100.0),
    regions={},
)


class MaterialsStageParams(MaterialsParams):
    """Region geometry plus the material values (``-c configs/materials/<model>.yaml``)."""

    model_config = ConfigDict(extra="forbid")
    model: MaterialModel = Field(default_factory=lambda: UNIFORM.model_copy(deep=True))


def compute(ctx: StageContext) -> None:
    """skin_labels (n_skin,), tet_labels (m,), E Pa, nu, eta Pa s, rho kg/m^3 per tet; PNG."""
    import numpy as np

    from physanim.fem.region_materials import tet_materials
    from physanim.mesh.params import REGION_NAMES
    from physanim.mesh.regions import plot_regions, region_areas, skin_regions, tet_regions

    params: MaterialsStageParams = ctx.params  # type: ignore[assignment]
    aligned, tets_out = ctx.input("align"), ctx.input("tetra")
    landmarks = dict(zip(aligned.attrs["landmark_names"], aligned["landmarks"][...], strict=True))
    scan_v, scan_f = aligned["scan_vertices"][...], aligned["scan_faces"][...]
    nodes, tets = tets_out["nodes"][...], tets_out["tets"][...]
    scan_labels = skin_regions(scan_v, landmarks, params)
    labels = tet_regions(nodes, tets, scan_v, scan_labels)
    mats = tet_materials(labels, params.model)
    ctx.write_record(mats)
    ctx.write("tet_labels", labels.astype(np.int8))
    ctx.write("scan_labels", scan_labels)
    plot_regions(scan_v, scan_f, scan_labels, ctx.files_dir / "regions.png", landmarks)
    areas = region_areas(scan_v, scan_f, scan_labels)
    names = ["default", *REGION_NAMES]
    ctx.out.attrs["region_names"] = names
    ctx.summary.update(
        model=params.model.name,
        region_area_cm2={n: round(float(a) * 1e4, 3) for n, a in zip(names, areas, strict=True)},
        tets_per_region={n: int((labels == i).sum()) for i, n in enumerate(names)},
    )


SPEC = StageSpec(
    name="materials",
    upstream=("align", "tetra"),
    params=MaterialsStageParams,
    version="1",
    compute=compute,
    doc="regions (Cheek, cphs L/R, Cheilion, cphi, Alare, default) -> per-tet materials",
)
