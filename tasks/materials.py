"""Stage ``materials``: facial regions from the feature points, per-tet E, nu, eta, rho."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from pydantic import ConfigDict, Field

from physanim.mesh.params import UNIFORM, MaterialModel, MaterialsParams
from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.align import AlignOutput
from tasks.tetra import TetraOutput

if TYPE_CHECKING:
    from physanim.fem.materials import TetMaterials


class MaterialsStageParams(MaterialsParams):
    """Region geometry plus the material values (``-c configs/materials/<model>.yaml``)."""

    model_config = ConfigDict(extra="forbid")
    model: MaterialModel = Field(default_factory=lambda: UNIFORM.model_copy(deep=True))


@dataclass(frozen=True)
class MaterialsOutput(StageOutput):
    """Per-tet materials of the m tets: ``E`` Pa, ``nu``, ``eta`` Pa s, ``rho`` kg/m^3 (m,);
    ``tet_labels`` (m,) int8 and ``scan_labels`` (N_scan,) region indices into
    ``region_names``; the fields a material law declares beyond those (``extra_names``, SI
    units in the names) as the columns of ``extra_values`` (m, k), None when there are none;
    ``files/regions.png`` shows the regions on the scan."""

    E: np.ndarray
    nu: np.ndarray
    eta: np.ndarray
    rho: np.ndarray
    tet_labels: np.ndarray
    scan_labels: np.ndarray
    region_names: list[str]
    extra_names: list[str] = field(default_factory=list)
    extra_values: np.ndarray | None = None

    def materials(self) -> TetMaterials:
        """The per-tet values as :class:`~physanim.fem.materials.TetMaterials`."""
        from physanim.fem.materials import TetMaterials

        columns = () if self.extra_values is None else self.extra_values.T
        extra = dict(zip(self.extra_names, columns, strict=True))
        return TetMaterials(self.E, self.nu, self.eta, self.rho, extra)


def compute(
    params: MaterialsStageParams,
    align: AlignOutput,
    tetra: TetraOutput,
    ctx: StageContext[MaterialsStageParams],
) -> MaterialsOutput:
    """skin_labels (n_skin,), tet_labels (m,), E Pa, nu, eta Pa s, rho kg/m^3 per tet; PNG."""
    from physanim.fem.region_materials import tet_materials
    from physanim.mesh import regions
    from physanim.mesh.params import REGION_NAMES
    from physanim.mesh.regions import plot_regions, region_areas, skin_regions, tet_regions
    from physanim.store.file_cache import FileCache, content_digest

    landmarks = align.landmark_positions()
    scan_v, scan_f = align.scan_vertices, align.scan_faces
    scan_labels = skin_regions(scan_v, landmarks, params)
    labels = tet_regions(tetra.nodes, tetra.tets, scan_v, scan_labels)
    mats = tet_materials(labels, params.model)
    # the regions do not change with the material model: the figure comes from the cache
    # on an edit (drawing its 55k triangles took most of the stage)
    figure = content_digest(
        Path(regions.__file__).read_bytes(), scan_v, scan_f, scan_labels, sorted(landmarks.items())
    )
    FileCache(ctx.dataset.run_dir / "cache" / "figures").make(
        ctx.files_dir / "regions.png",
        figure,
        lambda out: plot_regions(scan_v, scan_f, scan_labels, out, landmarks),
    )
    areas = region_areas(scan_v, scan_f, scan_labels)
    names = ["default", *REGION_NAMES]
    summary = dict(
        model=params.model.name,
        region_area_cm2={n: round(float(a) * 1e4, 3) for n, a in zip(names, areas, strict=True)},
        tets_per_region={n: int((labels == i).sum()) for i, n in enumerate(names)},
    )
    extra = np.column_stack(list(mats.extra.values())) if mats.extra else None
    return MaterialsOutput(
        mats.E, mats.nu, mats.eta, mats.rho, labels.astype(np.int8), scan_labels, names,
        list(mats.extra), extra, summary=summary,
    )  # fmt: skip


def model_name(params: MaterialsStageParams) -> str:
    """The material model's name: what tells variants of a run apart in the report."""
    return params.model.name


SPEC = StageSpec.typed(
    "materials",
    compute,
    version="1",
    doc="regions (Cheek, cphs L/R, Cheilion, cphi, Alare, default) -> per-tet materials",
    files={"regions.png": "Material regions"},
    label=model_name,
)
