"""Parameters of the face-model fit (``fit``), of how the face drives the FEM (``simulate``)
and of the inverse step that fits its actuation (``actuate``, ``simulate.actuation``)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from physanim.mesh.params import UNIFORM, TissueMaterial

#: facial regions of the fidelity report (``physanim.evaluate.fidelity.face_regions``) and of
#: exaggeration gestures (``DriveParams.actuation_scale``, with 'face' for the whole face)
FACE_REGIONS: tuple[str, ...] = ("mouth", "jaw_chin", "cheeks", "nose", "forehead")


class FitParams(BaseModel):
    """Regularised, bounded, confidence-weighted fit of pose, Shape Units and Action Units."""

    model_config = ConfigDict(extra="forbid")

    neutral_frames: int = Field(
        1, ge=1, description="number of leading neutral frames (count) averaged for the SU fit"
    )
    su_regularisation: float = Field(
        1e-9, ge=0.0, description="ridge weight on Shape Units (m^2 per unit^2)"
    )
    su_bound: float = Field(
        3.0, gt=0.0, description="Shape Units are bounded to +-su_bound (units)"
    )
    au_regularisation: float = Field(
        1e-9, ge=0.0, description="ridge weight on Action Units (m^2 per unit^2)"
    )
    au_temporal: float = Field(
        1e-9, ge=0.0, description="weight on AU change from the previous frame (m^2 per unit^2)"
    )
    au_max: float = Field(
        1.5, gt=0.0, description="Action Units are bounded to [0, au_max] (units)"
    )
    min_confidence: float = Field(
        0.3, ge=0.0, le=1.0, description="landmarks below this confidence (0-1) are ignored"
    )
    iterations: int = Field(
        6, ge=1, le=100, description="pose / unit alternations per frame (count)"
    )


class JawParams(BaseModel):
    """The mandible as a moving boundary of the tissue (``simulate.jaw``)."""

    model_config = ConfigDict(extra="forbid")

    enabled: bool = Field(
        True,
        description="turn the mandible's bone-side nodes with the estimated jaw rotation; "
        "false fixes every bone-side node (the seed)",
    )
    landmarks: list[str] | None = Field(
        None,
        description="tracked landmarks that ride on the mandible (default: those lying more "
        "than margin_m below the mouth line; the fitted model's chin when fewer than 2)",
    )
    margin_m: float = Field(
        0.008, gt=0.0, le=0.05, description="mandible landmarks lie this far below the mouth, m"
    )
    blend_m: float = Field(
        0.008,
        gt=0.0,
        le=0.05,
        description="bone-side nodes blend from skull (at the mouth line) to mandible over this "
        "height below it, m (measured at the skin in front of them)",
    )
    pivot_prior_m: tuple[float, float, float] = Field(
        (0.0, 0.005, -0.085),
        description="prior of the jaw (TMJ) axis position relative to the pronasale, m (actor "
        "frame: +x left, +y up, +z out of the face)",
    )
    pivot_prior_std_m: float = Field(
        0.01, gt=0.0, le=0.1, description="standard deviation of that prior, m"
    )
    axis_prior_std_deg: float = Field(
        10.0, gt=0.0, le=90.0, description="how far the hinge may tilt from left-right, deg"
    )
    noise_m: float = Field(
        5e-4, gt=0.0, le=0.01, description="tracking noise of the mandible landmarks, m"
    )


class DriveParams(BaseModel):
    """How the tracked face drives the simulated skin (``simulate.drive``)."""

    model_config = ConfigDict(extra="forbid")

    mode: Literal["actuation", "landmarks", "kinematic", "prescribed"] = Field(
        "actuation",
        description="'actuation' (default): the skin is moved by the tissue's active stress "
        "that the 'actuate' stage fitted to the captured motion at its basis material, held "
        "as the material is edited; 'landmarks': each tracked landmark pulls a skin patch by a "
        "spring; 'kinematic': every skin node is pulled towards the kinematic scan; "
        "'prescribed': each landmark's nearest skin node follows it exactly (the seed)",
    )
    actuation_scale: dict[str, float] = Field(
        default_factory=dict,
        description="'actuation' mode, exaggeration gesture: the fitted actuation of a face "
        f"region ({', '.join(FACE_REGIONS)}; by its patch centres) or of the whole "
        "'face' times this factor (dimensionless, >= 0; a region's own factor wins over "
        "'face'), e.g. {mouth: 1.5}",
    )
    landmarks: list[str] | None = Field(
        None, description="driving landmarks (default: every tracked landmark but 'exclude')"
    )
    exclude: list[str] = Field(
        default_factory=lambda: ["cphs_L", "cphs_R", "cphi_L", "cphi_R"],
        description="landmarks left to the physics (default: the philtrum ridges, top and "
        "bottom, whose material the regional models edit)",
    )
    radius_m: float = Field(
        0.005, gt=0.0, le=0.05, description="radius of each landmark's skin patch, m"
    )
    stiffness_N_per_m: float = Field(
        2e4, gt=0.0, le=1e9, description="spring stiffness of one landmark's whole patch, N/m"
    )
    stiffness_overrides_N_per_m: dict[str, float] = Field(
        default_factory=dict, description="per-landmark patch stiffness, N/m (name: value)"
    )
    kinematic_stiffness_N_per_m2: float = Field(
        5e7,
        gt=0.0,
        le=1e12,
        description="'kinematic' mode: spring stiffness per skin area, N/m per m^2",
    )

    @field_validator("actuation_scale")
    @classmethod
    def _known_scales(cls, value: dict[str, float]) -> dict[str, float]:
        unknown = sorted(set(value) - {*FACE_REGIONS, "face"})
        if unknown:
            raise ValueError(
                f"unknown region(s) {unknown}; use names among {[*FACE_REGIONS, 'face']}"
            )
        negative = {k: v for k, v in value.items() if not v >= 0.0}
        if negative:
            raise ValueError(f"factors must be >= 0, got {negative}")
        return value

    def scale_of(self, region: str | None) -> float:
        """The gesture factor of a patch in ``region`` (None: in none of them)."""
        face = self.actuation_scale.get("face", 1.0)
        return self.actuation_scale.get(region, face) if region else face


class ActuationParams(BaseModel):
    """The inverse step (stage ``actuate``): the active stress with which the static FEM at a
    fixed basis material reproduces the captured skin motion, per frame
    (``physanim.fem.inverse``)."""

    model_config = ConfigDict(extra="forbid")

    basis_material: TissueMaterial = Field(
        default_factory=lambda: UNIFORM.default.model_copy(deep=True),
        description="uniform material of the inverse step (the seed's uniform model): a "
        "fixed material, so no material edit runs the inverse step again (only E and nu "
        "matter: the step is static)",
    )
    patch_spacing_m: float = Field(
        0.008,
        ge=0.003,
        le=0.05,
        description="actuation patches: every tet lies within this distance of a patch "
        "centre, m; each patch reaches twice as far (5 deviatoric stress coefficients a patch)",
    )
    stress_cost_mm_per_kPa: float = Field(
        0.0015,
        gt=0.0,
        le=10.0,
        description="regularisation: an RMS active stress of 1 kPa over the tissue costs as "
        "much as an RMS skin misfit of this many mm (larger: smaller stresses, looser fit)",
    )
    robust_mm: float = Field(
        0.5,
        ge=0.0,
        le=10.0,
        description="Huber scale of each skin node's misfit, mm: beyond it the misfit counts "
        "linearly, not squared, so motion the skull and jaw conditions contradict does not call "
        "for extreme stresses (0: plain least squares)",
    )
    rate_cost_mm_per_kPa: float = Field(
        0.003,
        ge=0.0,
        le=10.0,
        description="temporal smoothing: an RMS change of the active stress of 1 kPa from one "
        "frame to the next costs as much as an RMS skin misfit of this many mm",
    )
    lip_patches: bool = Field(
        False,
        description="give each lip actuation patches of its own (none spans the lip seam, "
        "so the lips move apart more freely; demo: jaw-drop error 0.158 -> 0.142, but 65-137 "
        "lower-lip tets invert); false: patches by distance alone",
    )
    filled_weight: float = Field(
        0.5,
        ge=0.0,
        le=1.0,
        description="weight of a skin node's captured motion where the capture filled it from "
        "its neighbours (confidence 0) against one it saw (confidence 1); a node's weight is "
        "its skin area times filled_weight + (1 - filled_weight) x confidence",
    )
    landmark_weight: float = Field(
        0.0,
        ge=0.0,
        le=100.0,
        description="the tracked landmarks as targets beside the captured scan: each skin node "
        "of a landmark's patch (simulate.drive.radius_m; the landmarks and exclusions of "
        "simulate.drive) is also fitted to the landmark's motion, weighted by its skin area "
        "times this factor (0, default: the captured scan alone); they open the lips further "
        "where the capture sees them worst (demo, 0.25: lip gap at the jaw drop 11.9 -> "
        "12.4 mm against the actor's 13.9, the smile's error 0.124 -> 0.128)",
    )
