"""Parameters of the mesh stages (scan, align, tetra, materials) and the materials-file model."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, FiniteFloat, model_validator

#: Facial material regions of seed 004 (Tables 6.4-6.5); every other skin point is "default".
REGION_NAMES: tuple[str, ...] = ("Cheek", "cphs_L", "cphs_R", "Cheilion", "cphi", "Alare")

#: Feature points (physanim.face.landmarks names) that seed each region.
REGION_LANDMARKS: dict[str, tuple[str, ...]] = {
    "Cheek": ("cheek_L", "cheek_R"),
    "cphs_L": ("cphs_L",),
    "cphs_R": ("cphs_R",),
    "Cheilion": ("ch_L", "ch_R"),
    "cphi": ("cphi_L", "cphi_R"),
    "Alare": ("al_L", "al_R"),
}


class ScanParams(BaseModel):
    """Scan preparation: thin parts dropped, border slits zipped shut, isotropic remesh (the
    ``scan`` stage)."""

    model_config = ConfigDict(extra="forbid")

    min_width_m: float = Field(
        0.005,
        ge=0.0,
        le=0.03,
        description="Parts of the scan narrower than this along its border (slivers the "
        "scanner grazed, such as a strip under the jaw), or joined to the face through a "
        "narrower neck, are dropped, metres (0 keeps them).",
    )

    remesh_edge_length_m: float = Field(
        0.7e-3,
        gt=1e-4,
        le=2e-2,
        description="Target edge length of the isotropic scan remesh, metres "
        "(0.7 mm gives ~20-30k vertices on the cropped demo face).",
    )
    remesh_iterations: int = Field(
        6, ge=1, le=50, description="Isotropic remeshing iterations (count)."
    )
    notch_max_gap_m: float = Field(
        0.006,
        ge=0.0,
        le=0.05,
        description="Slits reaching into the scan from its border (creases the scanner lost) "
        "narrower than this across the view axis are zipped shut, metres (0 keeps them).",
    )
    notch_min_depth_m: float = Field(
        0.008,
        gt=0.0,
        le=0.2,
        description="Only slits longer than this along the border are closed, metres.",
    )
    notch_fair_band_m: float = Field(
        0.006,
        ge=0.0,
        le=0.03,
        description="The surface within this distance of a zipped slit is faired into a "
        "smooth ramp, metres: a slit whose sides lay at different depths is otherwise a "
        "steep wall, drawn as a fold (0 keeps it).",
    )


#: Settings that the ``align`` section had until the ``scan`` stage took them over.
_MOVED_TO_SCAN = (
    "scan", "scan_units", "remesh_edge_length_m", "remesh_iterations", "notch_max_gap_m",
    "notch_min_depth_m", "min_width_m", "notch_fair_band_m",
)  # fmt: skip


class AlignParams(BaseModel):
    """Alignment of the motion mesh to the prepared scan, lip seam, binding (``align``)."""

    model_config = ConfigDict(extra="forbid")

    @model_validator(mode="before")
    @classmethod
    def _moved_to_scan(cls, data: Any) -> Any:
        moved = [k for k in _MOVED_TO_SCAN if isinstance(data, dict) and k in data]
        if moved:
            raise ValueError(
                f"{', '.join(moved)} moved to the scan section: write scan: {{{moved[0]}: ...}}"
                " instead of align: {...} (the scan stage prepares the scan since align v4)"
            )
        return data

    scaling: Literal["similarity", "per_axis"] = Field(
        "per_axis",
        description="'similarity': Umeyama rotation + uniform scale; 'per_axis': rigid Umeyama "
        "then the seed's per-axis scaling about the nose tip (SPEC eqs 5.1-5.4).",
    )
    refine_iterations: int = Field(
        3, ge=0, le=50, description="Non-rigid refinement iterations (count; 0 disables)."
    )
    refine_smoothness: float = Field(
        0.1,
        ge=0.0,
        description="Weight of the Laplacian regulariser of the refinement displacement "
        "(dimensionless; larger keeps the wireframe shape).",
    )
    refine_max_distance_m: float = Field(
        0.01,
        gt=0.0,
        description="Wireframe vertices farther than this from the scan are not pulled, metres.",
    )
    lip_band_m: float = Field(
        0.015,
        gt=0.0,
        le=0.05,
        description="Between the mouth corners, scan and tissue within this height of the "
        "lip contact line are split into upper and lower lip by the lip seam, metres.",
    )
    binding_candidates: int = Field(
        8, ge=1, le=256, description="Initial candidate triangles per scan vertex (count)."
    )


class RefineRegion(BaseModel):
    """One region of finer tets: within ``radius_m`` of any of its feature points."""

    model_config = ConfigDict(extra="forbid")

    landmarks: tuple[str, ...] = Field(
        min_length=1, description="Feature points (physanim.face.landmarks names) it surrounds."
    )
    radius_m: float = Field(gt=0.0, le=0.1, description="Radius about each point, metres.")
    edge_length_m: float = Field(
        gt=1e-4, le=0.05, description="Target tet edge length inside the radius, metres."
    )


#: The regions ``tetra.refine`` grades finer by default: the lips and mouth corners (where the
#: lip gap, the philtrum and the mouth-corner figures are measured) and the eyelids.
DEFAULT_REFINE_REGIONS: dict[str, RefineRegion] = {
    "lips": RefineRegion(
        landmarks=("ch_L", "ch_R", "cphs_L", "cphs_R", "cphi_L", "cphi_R"),
        radius_m=0.012,
        edge_length_m=0.002,
    ),
    "eyelids": RefineRegion(
        landmarks=("ex_L", "ex_R", "pi_L", "pi_R"), radius_m=0.01, edge_length_m=0.0025
    ),
}


class RefineParams(BaseModel):
    """Regional refinement of the tet sizing field (``tetra.refine``): finer tets in named
    regions, coarser ones deep in the tissue, ``tetra.edge_length_m`` elsewhere at the skin."""

    model_config = ConfigDict(extra="forbid")

    enabled: bool = Field(False, description="Grade the sizing field (false: uniform tets).")
    regions: dict[str, RefineRegion] = Field(
        default_factory=lambda: dict(DEFAULT_REFINE_REGIONS),
        description="Named regions of finer tets (name -> landmarks, radius_m, edge_length_m).",
    )
    blend_m: float = Field(
        0.008,
        gt=0.0,
        le=0.1,
        description="Width beyond a region's radius over which its edge length grades into "
        "the surrounding one, metres.",
    )
    deep_edge_length_m: float | None = Field(
        0.005,
        gt=1e-4,
        le=0.05,
        description="Target edge length deep in the tissue, outside every region, metres. "
        "null: edge_length_m through the thickness.",
    )
    deep_depth_m: float = Field(
        0.006,
        gt=0.0,
        le=0.05,
        description="Depth below the skin at which deep_edge_length_m is reached (linear from "
        "the skin's edge length), metres.",
    )


class TetraParams(BaseModel):
    """Soft-tissue volume and tetrahedralisation (the ``tetra`` stage)."""

    model_config = ConfigDict(extra="forbid")

    thickness_default_m: float = Field(
        0.015, gt=0.0, le=0.05, description="Tissue thickness away from named areas, metres."
    )
    thickness_forehead_m: float = Field(
        0.010, gt=0.0, le=0.05, description="Tissue thickness above the glabella, metres."
    )
    thickness_nose_bridge_m: float = Field(
        0.010,
        gt=0.0,
        le=0.05,
        description="Tissue thickness along the nose bridge (glabella to pronasale), metres.",
    )
    thickness_cheek_m: float = Field(
        0.020, gt=0.0, le=0.05, description="Tissue thickness at the cheek points, metres."
    )
    thickness_falloff_m: float = Field(
        0.02,
        gt=0.0,
        le=0.2,
        description="Gaussian radius over which named thicknesses blend into the default, metres.",
    )
    normal_smoothing_iterations: int = Field(
        40,
        ge=0,
        le=1000,
        description="Laplacian smoothing passes of the offset normals and thickness (count).",
    )
    surface_edge_length_m: float = Field(
        0.0025,
        gt=1e-4,
        le=0.05,
        description="Edge length of the skin surface remesh fed to fTetWild, metres.",
    )
    edge_length_m: float = Field(
        0.0035, gt=1e-4, le=0.05, description="Target tetrahedron edge length, metres."
    )
    outside_edge_length_m: float | None = Field(
        0.02,
        gt=1e-4,
        le=0.2,
        description="fTetWild's target edge length away from the tissue, where its tets are "
        "discarded, metres; the target grows from edge_length_m at outside_growth. null: "
        "edge_length_m everywhere (on the demo about twice as slow).",
    )
    outside_growth: float = Field(
        2.0,
        gt=0.0,
        le=100.0,
        description="Growth of fTetWild's target edge length with distance outside the tissue "
        "(metres per metre).",
    )
    epsilon_rel: float = Field(
        1e-2,
        gt=0.0,
        le=0.05,
        description="fTetWild envelope: max surface deviation relative to the bounding-box "
        "diagonal (dimensionless).",
    )
    optimize: bool = Field(True, description="Let fTetWild optimise tet quality (slower).")
    stop_energy: float = Field(
        20.0,
        gt=3.0,
        le=1e3,
        description="fTetWild stops optimising once the conformal AMIPS energy is below this "
        "(dimensionless; 3 = all regular).",
    )
    max_opt_iterations: int = Field(
        4,
        ge=1,
        le=200,
        description="fTetWild optimisation passes at most (count). On the demo most runs meet "
        "stop_energy after 1-2 passes of 5-8 s each; a few kept going for 10 passes or more "
        "(fTetWild is not deterministic), which made tetra take from 20 s to 3 min.",
    )
    min_dihedral_deg: float = Field(
        1.0,
        ge=0.0,
        lt=60.0,
        description="fTetWild runs again (up to mesh_attempts runs in all) while its mesh's "
        "smallest dihedral angle is below this, and the best mesh is kept, deg. fTetWild is "
        "not deterministic: on two cores about 1 coarse face mesh in 10 had a 0.1-1 deg sliver.",
    )
    mesh_attempts: int = Field(
        3, ge=1, le=10, description="fTetWild runs at most, to meet min_dihedral_deg (count)."
    )
    mesh_file: str | None = Field(
        None,
        description="A tet mesh of this tissue volume to use instead of fTetWild's (fTetWild "
        "gives another mesh on every run): .npz with nodes (n, 3) m and tets (m, 4), its path "
        "relative to the working directory; refused when its volume is not the tissue's. "
        "null: fTetWild.",
    )
    sliver_dihedral_deg: float = Field(
        5.0, gt=0.0, lt=60.0, description="Tets with a dihedral angle below this are slivers, deg."
    )
    degenerate_volume_rel: float = Field(
        1e-9,
        gt=0.0,
        description="Tets with |volume| below this times edge_length_m^3 are degenerate "
        "(dimensionless).",
    )
    refine: RefineParams = Field(
        default_factory=RefineParams, description="regional refinement of the sizing field"
    )
    label_tolerance_rel: float = Field(
        0.3,
        gt=0.0,
        le=2.0,
        description="Boundary nodes within this times edge_length_m of the skin (bone) surface "
        "are labelled skin (bone) nodes (dimensionless).",
    )

    @model_validator(mode="after")
    def _refined_needs_sizing(self) -> TetraParams:
        if self.refine.enabled and self.outside_edge_length_m is None:
            raise ValueError(
                "tetra.refine.enabled needs tetra.outside_edge_length_m (the sizing field's "
                "coarse length outside the tissue); set it, e.g. 0.02"
            )
        return self

    @property
    def ftetwild_edge_length_m(self) -> float:
        """fTetWild's global target edge length, m: the coarsest its sizing field asks for
        (``outside_edge_length_m``; ``edge_length_m`` when that is null)."""
        return max(self.edge_length_m, self.outside_edge_length_m or 0.0)

    @property
    def finest_edge_length_m(self) -> float:
        """The smallest target edge length asked for anywhere, m (a refined region's, when
        ``refine.enabled``)."""
        regions = [r.edge_length_m for r in self.refine.regions.values()]
        return min([self.edge_length_m, *regions]) if self.refine.enabled else self.edge_length_m


class MaterialsParams(BaseModel):
    """Facial-region geometry (the ``materials`` stage); values come from a materials file."""

    model_config = ConfigDict(extra="forbid")

    radius_cheek_m: float = Field(
        0.012, gt=0.0, le=0.1, description="Radius of the Cheek regions about cheek_L/R, metres."
    )
    radius_cphs_m: float = Field(
        0.004,
        gt=0.0,
        le=0.1,
        description="Radius of cphs_L / cphs_R about their points, metres (the philtrum "
        "ridges are about 7 mm apart: wider regions would overlap).",
    )
    radius_cheilion_m: float = Field(
        0.010, gt=0.0, le=0.1, description="Radius of the Cheilion regions about ch_L/R, metres."
    )
    radius_cphi_m: float = Field(
        0.007, gt=0.0, le=0.1, description="Radius of the cphi regions about cphi_L/R, metres."
    )
    radius_alare_m: float = Field(
        0.008, gt=0.0, le=0.1, description="Radius of the Alare regions about al_L/R, metres."
    )

    def radius(self, region: str) -> float:
        """Radius in metres of a region of :data:`REGION_NAMES`."""
        key = {"cphs_L": "cphs", "cphs_R": "cphs"}.get(region, region.lower())
        return float(getattr(self, f"radius_{key}_m"))


class TissueMaterial(BaseModel):
    """Linear viscoelastic (Kelvin-Voigt) tissue constants of one region, plus any further
    per-tet field a material law declares (``simulate.law``) under ``fields``."""

    model_config = ConfigDict(extra="forbid")

    E_kPa: float = Field(gt=0.0, le=1e5, description="Young's modulus, kPa.")
    nu: float = Field(ge=0.0, lt=0.5, description="Poisson's ratio (dimensionless).")
    eta_Pa_s: float = Field(ge=0.0, le=1e6, description="Viscosity, Pa*s.")
    rho_kg_m3: float = Field(gt=0.0, le=1e4, description="Density, kg/m^3.")
    fields: dict[str, FiniteFloat] = Field(
        default_factory=dict,
        description="Per-tet fields a material law declares beyond E, nu, eta and rho: name "
        "with its SI unit (e.g. beta_s) -> value in that unit.",
    )


class MaterialModel(BaseModel):
    """A materials file (``configs/materials/*.yaml``): default values plus regional ones."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(description="Short name of the model.")
    description: str = Field("", description="Where the values come from.")
    default: TissueMaterial = Field(description="Values of tissue outside the named regions.")
    regions: dict[str, TissueMaterial] = Field(
        default_factory=dict,
        description=f"Per-region values; keys among {', '.join(REGION_NAMES)}.",
    )

    @model_validator(mode="after")
    def _known_regions(self) -> MaterialModel:
        unknown = sorted(set(self.regions) - set(REGION_NAMES))
        if unknown:
            raise ValueError(
                f"materials file '{self.name}': unknown region(s) {unknown}; "
                f"use names among {list(REGION_NAMES)}"
            )
        return self


#: The seed's uniform model (SPEC section 1, item 6), used when no materials file is merged.
UNIFORM = MaterialModel(
    name="uniform",
    description="Seed 004 uniform model",
    default=TissueMaterial(E_kPa=192.4, nu=0.495, eta_Pa_s=476.8, rho_kg_m3=1100.0),
    regions={},
)
