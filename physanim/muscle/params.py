"""Parameters of the muscle-driven arm (SPEC section 4, seed 000): arm, muscles, motion, solver.

Frames (planar, metres): the torso frame is the world frame, origin at the shoulder joint J0,
+x forward, +y up, gravity -y.  Link i's frame has its origin at joint i, +x along the link
towards joint i+1 and +y on the flexion side (positive joint angles rotate about +z).
Attachment points are (x, y) in the frame of the body they are fixed to.

Values and sources (seed 000 section 5.2 unless noted; "OCR" = the seed's text is garbled there):
- links: 20 cm long, 500 g cylinders (seed); radius 3 cm (OCR reads "6cm", taken as diameter).
- joint ranges: shoulder J0 -70..70 deg, elbow J1 0..140 deg (seed).
- motion: J0 starts at -70 deg and turns +140 deg, J1 starts at 140 deg and turns -140 deg in
  1 s (seed section 5.2, eqs 25-27): the arm rises while the elbow straightens.
- muscles: a flexor and an extensor per joint (seed section 3.1), total maximum isometric force
  40 kgf (seed: "about 40 kgf"), split 24/4/9/3 kgf: the flexors lift the arm and the load, the
  extensors are only needed when the arm is tensed.  Attachment points, optimal fibre lengths,
  tendon slack lengths and pennation angles are not legible in the OCR (it mentions lengths of
  about 20 cm and 7 cm next to the muscle description); they are our choices, found by a
  search that keeps the seed's three conditions producible (required force / force at full
  activation <= 0.85 with rigid tendons) with fibres 13-20 cm long staying within 0.5-1.15 l0
  and moment arms 1-6.5 cm.  Straight-line paths need the shoulder muscles' origins far from
  the joint (24 cm above/below it, standing in for the deltoid's wrap over the humeral head) to
  keep a usable moment arm over the +-70 deg range.  Pennation 5-10 deg: typical arm muscles.
- model: maximum shortening velocity 10 l0/s (Zajac 1989); specific tension 3.5 kgf/cm^2
  (seed eq 19).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from physanim.config.loader import deep_merged

KGF = 9.80665  # N per kilogram-force


class LinkParams(BaseModel):
    """One rigid link (a solid cylinder) and the revolute joint at its proximal end."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field("link", description="link name, unique in the arm")
    length: float = Field(0.2, gt=0, le=2.0, description="link length, m")
    mass: float = Field(0.5, gt=0, le=100.0, description="link mass, kg (solid cylinder)")
    radius: float = Field(0.03, gt=0, le=0.5, description="cylinder radius, m")
    joint_min_deg: float = Field(-70.0, ge=-180, le=180, description="joint lower limit, deg")
    joint_max_deg: float = Field(70.0, ge=-180, le=180, description="joint upper limit, deg")

    @model_validator(mode="after")
    def _limits_ordered(self) -> LinkParams:
        if self.joint_min_deg >= self.joint_max_deg:
            raise ValueError(
                f"link {self.name!r}: joint_min_deg ({self.joint_min_deg}) must be below "
                f"joint_max_deg ({self.joint_max_deg})"
            )
        return self


class MuscleParams(BaseModel):
    """One musculotendon unit: a straight line from origin to insertion (seed section 3.3)."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field("muscle", description="muscle name, unique in the arm")
    origin_body: str = Field("torso", description="body of the origin: the base or a link name")
    origin: tuple[float, float] = Field((0.0, 0.1), description="origin (x, y) in its body, m")
    insertion_body: str = Field("upper_arm", description="body of the insertion (a link name)")
    insertion: tuple[float, float] = Field(
        (0.05, 0.0), description="insertion (x, y) in its body, m"
    )
    optimal_fibre_length: float = Field(0.1, gt=0, le=1.0, description="l0, m")
    tendon_slack_length: float = Field(0.03, gt=0, le=1.0, description="tendon slack length, m")
    max_isometric_force: float = Field(100.0, gt=0, le=1e5, description="F0, N (1 kgf = 9.80665 N)")
    pennation_deg: float = Field(
        5.0, ge=0, lt=60, description="pennation angle at optimal fibre length, deg"
    )


def _default_links() -> list[LinkParams]:
    return [
        LinkParams(name="upper_arm", joint_min_deg=-70.0, joint_max_deg=70.0),
        LinkParams(name="forearm", joint_min_deg=0.0, joint_max_deg=140.0),
    ]


def _default_muscles() -> list[MuscleParams]:
    return [
        MuscleParams(
            name="shoulder_flexor",
            origin_body="torso",
            origin=(0.0, 0.24),
            insertion_body="upper_arm",
            insertion=(0.065, 0.0),
            optimal_fibre_length=0.2,
            tendon_slack_length=0.075,
            max_isometric_force=24 * KGF,
            pennation_deg=10.0,
        ),
        MuscleParams(
            name="shoulder_extensor",
            origin_body="torso",
            origin=(0.0, -0.24),
            insertion_body="upper_arm",
            insertion=(0.065, 0.0),
            optimal_fibre_length=0.2,
            tendon_slack_length=0.075,
            max_isometric_force=4 * KGF,
            pennation_deg=10.0,
        ),
        MuscleParams(
            name="elbow_flexor",
            origin_body="upper_arm",
            origin=(0.04, 0.005),
            insertion_body="forearm",
            insertion=(0.04, 0.016),
            optimal_fibre_length=0.175,
            tendon_slack_length=0.01,
            max_isometric_force=9 * KGF,
            pennation_deg=5.0,
        ),
        MuscleParams(
            name="elbow_extensor",
            origin_body="upper_arm",
            origin=(0.04, -0.015),
            insertion_body="forearm",
            insertion=(-0.025, -0.012),
            optimal_fibre_length=0.13,
            tendon_slack_length=0.04,
            max_isometric_force=3 * KGF,
            pennation_deg=10.0,
        ),
    ]


class ArmParams(BaseModel):
    """The planar arm: a serial chain of links on a fixed base, muscles, and a load in the hand."""

    model_config = ConfigDict(extra="forbid")

    base_name: str = Field("torso", description="name of the fixed base body (world frame)")
    links: list[LinkParams] = Field(default_factory=_default_links, min_length=1)
    muscles: list[MuscleParams] = Field(default_factory=_default_muscles, min_length=1)
    load_mass: float = Field(0.0, ge=0, le=50.0, description="point mass in the hand, kg")

    @model_validator(mode="after")
    def _names_resolve(self) -> ArmParams:
        bodies = [self.base_name] + [link.name for link in self.links]
        if len(set(bodies)) != len(bodies):
            raise ValueError(f"arm: body names must be unique, got {bodies}")
        for m in self.muscles:
            for field in ("origin_body", "insertion_body"):
                if getattr(m, field) not in bodies:
                    raise ValueError(
                        f"arm.muscles[{m.name}].{field} = {getattr(m, field)!r} is not a body; "
                        f"use one of {bodies}"
                    )
            if m.origin_body == m.insertion_body:
                raise ValueError(
                    f"arm.muscles[{m.name}]: origin and insertion are both on "
                    f"{m.origin_body!r}; a muscle must cross at least one joint"
                )
        return self

    def body_index(self, name: str) -> int:
        """0 for the base, i + 1 for link i."""
        return [self.base_name, *(link.name for link in self.links)].index(name)


class MotionParams(BaseModel):
    """Seed trajectory (SPEC section 4): theta_i goes from start_deg[i] to start + range."""

    model_config = ConfigDict(extra="forbid")

    start_deg: list[float] = Field([-70.0, 140.0], description="joint angles at t = 0, deg")
    range_deg: list[float] = Field([140.0, -140.0], description="joint excursions, deg")
    duration: float = Field(1.0, gt=0, le=60.0, description="motion duration, s")
    sample_rate: float = Field(100.0, ge=10, le=10000, description="time samples per second, Hz")


class ModelParams(BaseModel):
    """Muscle model and force-sharing settings."""

    model_config = ConfigDict(extra="forbid")

    force_sharing: Literal["seed_rule", "static_optimisation"] = Field(
        "static_optimisation",
        description="seed_rule: the muscle whose moment matches the torque sign carries it; "
        "static_optimisation: minimise the sum of squared activations (the reported ones)",
    )
    co_contraction: float = Field(
        0.0,
        ge=0,
        le=1,
        description="minimum activation of every muscle (co-contraction of a tensed arm), 0-1",
    )
    max_shortening_velocity: float = Field(
        10.0, gt=0, le=50, description="v_max at full activation, optimal fibre lengths per s"
    )
    rest_vmax_fraction: float = Field(
        0.5,
        gt=0,
        le=1,
        description="v_max at zero activation as a fraction of v_max at full activation "
        "(1 = force-velocity independent of activation)",
    )
    sharing_iterations: int = Field(
        20,
        ge=1,
        le=100,
        description="most fixed-point passes between force sharing and fibre state (they "
        "stop once the tendon forces change by less than 1e-9 F0)",
    )


class ShapeParams(BaseModel):
    """Volume-preserving spindle muscle bellies (seed section 5.1)."""

    model_config = ConfigDict(extra="forbid")

    specific_tension: float = Field(
        343232.75,  # 3.5 kgf/cm^2
        gt=0,
        le=1e7,
        description="maximum force per physiological cross-section, Pa (3.5 kgf/cm^2)",
    )
    n_around: int = Field(16, ge=3, le=256, description="mesh vertices around the spindle")
    n_along: int = Field(17, ge=3, le=256, description="mesh rings along the spindle")


class ArmStudyParams(BaseModel):
    """Everything one arm condition needs: arm, motion, model and shape (configs/arm/*.yaml)."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field("free", description="condition name, used in plot titles and file names")
    arm: ArmParams = Field(default_factory=ArmParams)
    motion: MotionParams = Field(default_factory=MotionParams)
    model: ModelParams = Field(default_factory=ModelParams)
    shape: ShapeParams = Field(default_factory=ShapeParams)

    @model_validator(mode="after")
    def _motion_matches_arm(self) -> ArmStudyParams:
        n = len(self.arm.links)
        for field in ("start_deg", "range_deg"):
            if len(getattr(self.motion, field)) != n:
                raise ValueError(
                    f"motion.{field} has {len(getattr(self.motion, field))} entries but the arm "
                    f"has {n} joints; give one angle per joint"
                )
        return self


class ArmConditions(BaseModel):
    """Several conditions solved side by side: each entry of ``conditions`` merges over ``base``."""

    model_config = ConfigDict(extra="forbid")

    base: ArmStudyParams = Field(default_factory=ArmStudyParams)
    conditions: dict[str, dict[str, Any]] = Field(
        default_factory=lambda: {"free": {}},
        min_length=1,
        description="condition name -> overrides of base (same keys as base)",
    )

    def resolved(self) -> dict[str, ArmStudyParams]:
        """Each condition as full, validated params (its ``name`` set to the condition's)."""
        base = self.base.model_dump()
        return {
            name: ArmStudyParams.model_validate(deep_merged(base, {**over, "name": name}))
            for name, over in self.conditions.items()
        }

    @model_validator(mode="after")
    def _conditions_valid(self) -> ArmConditions:
        for name, over in self.conditions.items():
            try:
                ArmStudyParams.model_validate(deep_merged(self.base.model_dump(), over))
            except ValueError as exc:
                raise ValueError(f"condition {name!r}: {exc}") from None
        return self
