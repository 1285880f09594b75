"""Keyframe animation with partial dynamics (seed 001 sections 2.5 and 3).

A keyframe file (YAML, schema :class:`KeyframeSpec`) gives key frames with joint angles
(and optional velocities), the intervals and sub-structures to simulate passively,
per-joint friction factors (per frame), world constraints and optionally a root path: the
base follows a natural cubic spline through given points, one sample per frame placed by a
spacing rule (seed 002), and a heading joint can turn the figure along it.  Unsimulated joints are
interpolated (quadratic from theta_1, theta'_1, theta_2, or cubic Hermite); a simulated
interval starts from the interpolated state and hands its end state to a cubic Hermite
segment towards the next key.  Missing key velocities default to central differences.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from physanim.dynamics.contact import Environment
from physanim.dynamics.figure import Figure
from physanim.dynamics.interpolation import catmull_rom_velocities, evaluate, hermite, quadratic
from physanim.dynamics.params import KeyframeParams
from physanim.dynamics.passive import passive_step
from physanim.dynamics.placement import Placement, RootPath, WorldConstraint, place_in_world

Vec3 = tuple[float, float, float]


class KeySpec(BaseModel):
    """One key: frame number, angles and optional velocities (joints not named keep
    the previous key's angle; the first key's default is 0)."""

    model_config = ConfigDict(extra="forbid")

    frame: int = Field(ge=0, description="Frame number of the key.")
    angles: dict[str, float] = Field(default_factory=dict, description="Joint angles (units).")
    velocities: dict[str, float] = Field(
        default_factory=dict, description="Joint velocities (units per second)."
    )


class SimulateSpec(BaseModel):
    """Simulate the keys' intervals from_key..to_key (key indices) for the union of the
    listed subtrees (a joint and all its descendants) and single joints."""

    model_config = ConfigDict(extra="forbid")

    from_key: int = Field(ge=0, description="Index of the first key of the interval.")
    to_key: int = Field(ge=1, description="Index of the last key of the interval.")
    subtrees: list[str] = Field(default_factory=list, description="Roots of sub-structures.")
    joints: list[str] = Field(default_factory=list, description="Single joints.")


class ConstraintSpec(BaseModel):
    """World constraint between two keys: ``pin`` a joint, or ``gravity`` with contact
    (``joint`` pinned while in contact; default the joint nearest the contact)."""

    model_config = ConfigDict(extra="forbid")

    type: Literal["pin", "gravity"]
    from_key: int = Field(ge=0, description="Index of the key where it starts.")
    to_key: int = Field(ge=1, description="Index of the key where it ends.")
    joint: str | None = Field(default=None, description="Joint to pin.")


class BoxSpec(BaseModel):
    """Axis-aligned box (a platform), corners in m."""

    model_config = ConfigDict(extra="forbid")

    min: Vec3
    max: Vec3


class StartSpec(BaseModel):
    """Initial placement: ``joint`` (or the base, if None) at ``position`` m."""

    model_config = ConfigDict(extra="forbid")

    joint: str | None = None
    position: Vec3 = (0.0, 0.0, 0.0)


class WorldSpec(BaseModel):
    """Gravity (m/s^2, y up), ground height (m), platforms, start placement, constraints."""

    model_config = ConfigDict(extra="forbid")

    gravity: Vec3 = (0.0, -9.81, 0.0)
    ground_height: float = 0.0
    platforms: list[BoxSpec] = Field(default_factory=list)
    start: StartSpec = Field(default_factory=StartSpec)
    constraints: list[ConstraintSpec] = Field(default_factory=list)


class PathSpec(BaseModel):
    """Root path (seed 002): between keys ``from_key`` and ``to_key`` the base (pelvis
    centre) follows the natural cubic spline through ``points``, one sample per frame."""

    model_config = ConfigDict(extra="forbid")

    points: list[Vec3] = Field(min_length=3, description="Spline data points (world), m.")
    spacing: Literal["uniform", "arc", "curvature"] | list[float] = Field(
        default="arc",
        description="Timing: 'uniform' (equal spline-parameter steps), 'arc' (constant "
        "speed), 'curvature' (equal curvature integral: slow in bends) or one relative "
        "distance per frame step (frames - 1 numbers >= 0).",
    )
    from_key: int = Field(default=0, ge=0, description="Index of the key where the path starts.")
    to_key: int | None = Field(default=None, ge=1, description="Key where it ends (last: None).")
    on_ground: bool = Field(
        default=True,
        description="Lift the base each frame until the lowest capsule touches the ground or "
        "a platform (the points' heights are then ignored).",
    )
    heading_joint: str | None = Field(
        default=None,
        description="Joint about world +y (e.g. pelvis_y) that turns the figure to face along "
        "the path; the keys' angles for it are added to the heading.",
    )
    extra_point: Literal["reflect", "none"] = Field(
        default="reflect",
        description="'reflect': an extra point past the end keeps the last sample from drifting "
        "(seed 002); 'none': the plain natural spline.",
    )


class KeyframeSpec(BaseModel):
    """Keyframe file schema."""

    model_config = ConfigDict(extra="forbid")

    name: str = "keyframes"
    figure: str = Field(description="Figure YAML, relative to the keyframe file.")
    fps: float = Field(default=30.0, gt=0.0, description="Frames per second.")
    units: Literal["deg", "rad"] = Field(default="deg", description="Angle units of the keys.")
    interpolation: Literal["hermite", "quadratic"] = "hermite"
    keys: list[KeySpec] = Field(min_length=2)
    simulate: list[SimulateSpec] = Field(default_factory=list)
    friction: dict[str, float] = Field(
        default_factory=dict,
        description="Velocity factor per frame in [0, 1] by joint name; 'default' for the rest.",
    )
    world: WorldSpec = Field(default_factory=WorldSpec)
    path: PathSpec | None = Field(default=None, description="Root path of the base (optional).")

    def path_keys(self) -> tuple[int, int]:
        """(from_key, to_key) of the root path; to_key defaults to the last key."""
        if self.path is None:
            raise ValueError("the keyframe file has no 'path'")
        last = len(self.keys) - 1 if self.path.to_key is None else self.path.to_key
        return self.path.from_key, last

    @model_validator(mode="after")
    def _check(self) -> KeyframeSpec:
        frames = [k.frame for k in self.keys]
        if any(b <= a for a, b in zip(frames, frames[1:], strict=False)):
            raise ValueError(f"keys: frames must increase strictly, got {frames}")
        for where, items in (("simulate", self.simulate), ("constraints", self.world.constraints)):
            for item in items:
                if not item.from_key < item.to_key < len(self.keys):
                    raise ValueError(
                        f"{where}: need from_key < to_key < {len(self.keys)} (number of keys), "
                        f"got {item.from_key}..{item.to_key}"
                    )
        for name, f in self.friction.items():
            if not 0.0 <= f <= 1.0:
                raise ValueError(f"friction[{name!r}] = {f} is outside [0, 1]")
        if self.path is not None:
            self._check_path()
        return self

    def _check_path(self) -> None:
        first, last = self.path_keys()
        if not first < last < len(self.keys):
            raise ValueError(
                f"path: need from_key < to_key < {len(self.keys)} (number of keys), "
                f"got {first}..{last}"
            )
        f0, f1 = self.keys[first].frame, self.keys[last].frame
        spacing = self.path.spacing if self.path is not None else "arc"
        if not isinstance(spacing, str) and (
            len(spacing) != f1 - f0 or min(spacing) < 0 or sum(spacing) <= 0
        ):
            raise ValueError(
                f"path.spacing: give {f1 - f0} relative distances >= 0 (one per frame step "
                f"from frame {f0} to {f1}), got {len(spacing)}"
            )
        for i, c in enumerate(self.world.constraints):
            a, b = self.keys[c.from_key].frame, self.keys[c.to_key].frame
            if a < f1 and f0 < b:
                raise ValueError(
                    f"world.constraints[{i}] (frames {a}..{b}) overlaps the path (frames "
                    f"{f0}..{f1}); the path places the base there: drop one or shift it"
                )

    @classmethod
    def from_yaml(cls, path: str | Path) -> KeyframeSpec:
        """Load a keyframe file; ``figure`` is resolved relative to the file."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"keyframe file {path} does not exist")
        with path.open() as f:
            d = yaml.safe_load(f)
        try:
            spec = cls.model_validate(d)
        except ValidationError as e:
            raise ValueError(f"{path}: invalid keyframe file:\n{e}") from None
        return spec.model_copy(update={"figure": str((path.parent / spec.figure).resolve())})


@dataclass(frozen=True)
class KeyframeResult:
    """Animation: ``times`` (F,) s; ``q`` (F, n) rad; ``qd`` (F, n) rad/s; ``simulated``
    (F, n) bool (joint driven by dynamics in the interval ending at that frame) and the
    world placement (base positions, COM, contact, pinned joint, clearance)."""

    times: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    simulated: np.ndarray
    placement: Placement


def _joint(fig: Figure, name: str, where: str) -> int:
    try:
        return fig.index(name)
    except KeyError as e:
        raise ValueError(f"{where}: {e.args[0]}") from None


def animate_joints(
    fig: Figure,
    spec: KeyframeSpec,
    *,
    substeps: int = 10,
    method: Literal["crba", "rnea"] = "crba",
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint trajectories q, qd (F, n) rad, rad/s and the simulated mask (F, n).

    ``substeps`` dynamics steps per frame; per-frame friction factors f become
    f ** (1 / substeps) per step, so results do not depend on the substep count's
    friction scaling (with substeps = 1 this is exactly the seed's scheme).
    """
    n = fig.n_dof
    scale = np.pi / 180.0 if spec.units == "deg" else 1.0
    frames = np.array([k.frame for k in spec.keys])
    times = frames / spec.fps
    nk = len(frames)
    angles = np.zeros((nk, n))
    given_v = np.full((nk, n), np.nan)
    current = np.zeros(n)
    for k, key in enumerate(spec.keys):
        for name, value in key.angles.items():
            current[_joint(fig, name, f"keys[{k}].angles")] = value * scale
        angles[k] = current
        for name, value in key.velocities.items():
            given_v[k, _joint(fig, name, f"keys[{k}].velocities")] = value * scale
    key_v = np.where(np.isnan(given_v), catmull_rom_velocities(times, angles), given_v)
    sim = np.zeros((nk - 1, n), dtype=bool)
    for i, s in enumerate(spec.simulate):
        mask = np.zeros(n, dtype=bool)
        for name in s.subtrees:
            _joint(fig, name, f"simulate[{i}].subtrees")
            mask |= fig.subtree(name)
        for name in s.joints:
            mask[_joint(fig, name, f"simulate[{i}].joints")] = True
        sim[s.from_key : s.to_key] |= mask
    fric = fig.friction.copy()
    if "default" in spec.friction:
        fric[:] = spec.friction["default"]
    for name, value in spec.friction.items():
        if name != "default":
            fric[_joint(fig, name, "friction")] = value
    fric_step = fric ** (1.0 / substeps)

    nf = frames[-1] + 1
    q = np.zeros((nf, n))
    qd = np.zeros((nf, n))
    simulated = np.zeros((nf, n), dtype=bool)
    q0, v0 = angles[0], np.where(np.isnan(given_v[0]), 0.0, given_v[0])
    if spec.interpolation == "hermite":
        v0 = key_v[0]
    prev_sim = np.zeros(n, dtype=bool)
    dt = 1.0 / (spec.fps * substeps)
    for k in range(nk - 1):
        h = times[k + 1] - times[k]
        cubic = hermite(q0, v0, angles[k + 1], key_v[k + 1], h)
        coef = cubic if spec.interpolation == "hermite" else quadratic(q0, v0, angles[k + 1], h)
        coef[prev_sim] = cubic[prev_sim]
        free = sim[k]
        span = np.arange(frames[k], frames[k + 1] + 1)
        th, v, _ = evaluate(coef, (span - frames[k]) / spec.fps)
        if free.any():
            qc, vc = q0.copy(), v0.copy()
            for j in range((frames[k + 1] - frames[k]) * substeps):
                _, _, acc = evaluate(coef, j * dt)
                r = passive_step(
                    fig,
                    qc,
                    vc,
                    dt,
                    free=free,
                    prescribed_qdd=acc,
                    friction=fric_step,
                    gravity=spec.world.gravity,
                    method=method,
                )
                pth, pv, _ = evaluate(coef, (j + 1) * dt)
                qc, vc = np.where(free, r.q, pth), np.where(free, r.qd, pv)
                if (j + 1) % substeps == 0:
                    f = (j + 1) // substeps
                    th[f, free], v[f, free] = qc[free], vc[free]
            simulated[span[1:]] |= free
        q[span], qd[span] = th, v
        end_q, end_v = th[-1], v[-1]
        q0 = np.where(free, end_q, angles[k + 1])
        next_v = key_v[k + 1] if spec.interpolation == "hermite" else end_v
        v0 = np.where(free, end_v, np.where(np.isnan(given_v[k + 1]), next_v, given_v[k + 1]))
        prev_sim = free
        if progress is not None:
            progress(k + 1, nk - 1)
    return q, qd, simulated


def world_constraints(fig: Figure, spec: KeyframeSpec) -> list[WorldConstraint]:
    """The file's constraints in frame numbers and joint indices."""
    frames = [k.frame for k in spec.keys]
    out = []
    for i, c in enumerate(spec.world.constraints):
        if c.type == "pin" and c.joint is None:
            raise ValueError(f"world.constraints[{i}]: a 'pin' constraint needs 'joint'")
        joint = -1 if c.joint is None else _joint(fig, c.joint, f"world.constraints[{i}]")
        out.append(WorldConstraint(c.type, frames[c.from_key], frames[c.to_key], joint))
    return out


def environment(spec: KeyframeSpec) -> Environment:
    """Ground and platforms of the keyframe file's world."""
    w = spec.world
    boxes = [(np.asarray(b.min, float), np.asarray(b.max, float)) for b in w.platforms]
    return Environment(ground_height=w.ground_height, boxes=boxes)


def root_path(spec: KeyframeSpec) -> tuple[RootPath, np.ndarray]:
    """The file's root path as per-frame base positions, and the heading (k,) rad about +y
    (0 faces +z) of the path's tangent at those frames, unwrapped."""
    from physanim.spline import path_samples

    path = spec.path
    if path is None:
        raise ValueError("the keyframe file has no 'path'")
    first, last = spec.path_keys()
    f0, f1 = spec.keys[first].frame, spec.keys[last].frame
    spline, t = path_samples(
        np.asarray(path.points, float),
        f1 - f0 + 1,
        path.spacing,
        extra_point=None if path.extra_point == "none" else path.extra_point,
    )
    tangent = spline(t, 1)
    heading = np.unwrap(np.arctan2(tangent[:, 0], tangent[:, 2]))
    return RootPath(f0, spline(t), path.on_ground), heading


def _turn_along_path(
    fig: Figure,
    spec: KeyframeSpec,
    q: np.ndarray,
    qd: np.ndarray,
    simulated: np.ndarray,
    path: RootPath,
    heading: np.ndarray,
) -> None:
    """Add the heading (held before and after the path) to the heading joint, in place."""
    name = spec.path.heading_joint if spec.path is not None else None
    if name is None:
        return
    j = _joint(fig, name, "path.heading_joint")
    if simulated[:, j].any():
        raise ValueError(
            f"path.heading_joint: {name!r} is simulated; it cannot also follow the path"
        )
    first = path.first_frame
    full = np.empty(len(q))
    full[:first] = heading[0]
    full[first : first + len(heading)] = heading
    full[first + len(heading) :] = heading[-1]
    rate = np.zeros(len(q))
    rate[first : first + len(heading)] = np.gradient(heading, 1.0 / spec.fps)
    q[:, j] += full
    qd[:, j] += rate


def run_keyframes(
    fig: Figure,
    spec: KeyframeSpec,
    *,
    params: KeyframeParams | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> KeyframeResult:
    """Joint animation plus world placement for a keyframe file (see module docstring)."""
    p = params or KeyframeParams()
    q, qd, simulated = animate_joints(
        fig, spec, substeps=p.substeps, method=p.method, progress=progress
    )
    path = None
    if spec.path is not None:
        path, heading = root_path(spec)
        _turn_along_path(fig, spec, q, qd, simulated, path, heading)
    start = spec.world.start
    placement = place_in_world(
        fig,
        q,
        spec.fps,
        environment(spec),
        world_constraints(fig, spec),
        start_position=np.asarray(start.position, float),
        start_joint=-1 if start.joint is None else _joint(fig, start.joint, "world.start"),
        gravity=spec.world.gravity,
        root_path=path,
        params=p,
    )
    return KeyframeResult(np.arange(len(q)) / spec.fps, q, qd, simulated, placement)
