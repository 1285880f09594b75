"""Parameters of the face-model fit (``fit``), of how the face drives the FEM (``simulate``)
and of the inverse step that fits its actuation (``actuate``, ``simulate.actuation``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from physanim.mesh.params import UNIFORM, TissueMaterial

#: facial regions of the fidelity report (``physanim.evaluate.fidelity.face_regions``) and of
#: exaggeration gestures (``DriveParams.actuation_scale``, with 'face' for the whole face)
FACE_REGIONS: tuple[str, ...] = ("mouth", "jaw_chin", "cheeks", "nose", "forehead")


def region_values(
    value: dict[str, float], extra: str, valid: Callable[[float], bool], rule: str
) -> dict[str, float]:
    """``value`` (face region or ``extra`` -> number) when every name is known and every
    number ``valid``; else ValueError naming the offenders and the ``rule``."""
    names = [*FACE_REGIONS, extra]
    unknown = sorted(set(value) - set(names))
    if unknown:
        raise ValueError(f"unknown region(s) {unknown}; use names among {names}")
    bad = {k: v for k, v in value.items() if not valid(v)}
    if bad:
        raise ValueError(f"{rule}, got {bad}")
    return value


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
    pivot_bound_std: float = Field(
        3.0,
        gt=0.0,
        le=100.0,
        description="the estimated pivot stays within this many pivot_prior_std_m of the prior "
        "in each coordinate (chin skin moving while the jaw stays, as in a lip press, was read "
        "as a turn about a pivot 50 mm in front of the TMJ)",
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
    actuation_scale_with: list[str] = Field(
        default_factory=list,
        description="the gesture follows these action units of the fit (its au_names, e.g. "
        "lip_corner_puller_L): actuation_scale applies in full where the most active of them "
        "peaks and fades to none where they rest, so a smile gesture leaves the jaw drop "
        "alone (empty: the factors apply in every frame)",
    )
    actuation_scale_full_span: float = Field(
        0.4,
        gt=0.0,
        le=2.0,
        description="actuation_scale_with: a unit's activity is measured from its least to its "
        "largest value over the run, or over this many action units where it varies less (a "
        "lip corner puller's 1 moves the mouth corner 7 mm), so on a performance without the "
        "expression the fit's leak of the unit is not taken for its peak; action units",
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
        return region_values(value, "face", lambda v: v >= 0.0, "factors must be >= 0")

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
        0.006,
        ge=0.003,
        le=0.05,
        description="actuation patches: every tet above deep_below_m lies within this "
        "distance of a patch centre, m; each patch reaches twice as far (5 deviatoric stress "
        "coefficients a patch; library: 8 mm -> 6 mm took the FEM within 0.03 of the captured "
        "scan at 17 -> 23 of 24 peaks, the demo's inverse step 372 patches, about 6 s)",
    )
    stress_cost_mm_per_kPa: float = Field(
        0.0003,
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
    region_stress_cost_mm_per_kPa: dict[str, float] = Field(
        default_factory=lambda: {"mouth": 0.0015, "deep": 0.0015},
        description="the stress cost of the patches centred in a face region "
        f"({', '.join(FACE_REGIONS)}) or in the 'deep' tissue (farther than deep_below_m "
        "under the skin, where no facial muscle lies), mm/kPa, in place of "
        "stress_cost_mm_per_kPa (the larger where both apply; the rate cost stays the same). "
        "Default: the lips (whose tets the jaw drop stretches most) and the deep tissue (the "
        "skin barely constrains it; thin tets at the bone there) five times stiffer",
    )
    deep_below_m: float = Field(
        0.010,
        gt=0.0,
        le=0.1,
        description="tissue farther than this under the skin (from its nearest skin node), m, "
        "is 'deep': no facial muscle lies there, so no patch is centred there (deep_centres) "
        "and a patch that is takes the deep cost of region_stress_cost_mm_per_kPa",
    )
    deep_centres: bool = Field(
        False,
        description="patch centres in the deep tissue too (farther than deep_below_m under "
        "the skin); false (default): centres only in the layer above it, where the facial "
        "muscles lie, the deep tissue taking the stress of the nearest patches (demo: 459 -> "
        "372 patches, the same fidelity at 0.6 of the inverse step's cost)",
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
        "so the lips move apart more freely; demo: the jaw drop's error over the captured "
        "scan's +0.036 -> +0.023, but its lower lip's inverted tets 128 -> 253); false: "
        "patches by distance alone",
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

    @field_validator("region_stress_cost_mm_per_kPa")
    @classmethod
    def _known_costs(cls, value: dict[str, float]) -> dict[str, float]:
        return region_values(
            value, "deep", lambda v: 0.0 < v <= 10.0, "costs must be in (0, 10] mm/kPa"
        )

    def patch_cost(self, regions: list[str | None], depths: list[float]) -> list[float]:
        """Each patch's cost factor (P,) against ``stress_cost_mm_per_kPa``, from the face
        regions (P,) of the patch centres (None: in none) and their ``depths`` (P,) m under
        the skin: a region's own cost, or the deep tissue's where that is larger."""
        own, base = self.region_stress_cost_mm_per_kPa, self.stress_cost_mm_per_kPa
        costs = [own.get(r, base) if r else base for r in regions]
        if "deep" in own:
            deep = np.asarray(depths) > self.deep_below_m
            costs = [max(c, own["deep"]) if d else c for c, d in zip(costs, deep, strict=True)]
        return [c / base for c in costs]
