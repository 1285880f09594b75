"""Articulated figure: a tree of links joined to their parents by 1-DOF revolute joints.

Every link ``i`` owns the joint that connects it to its parent.  The joint sits at
``offset`` (m, parent-link frame) and turns about ``axis`` (unit, parent frame; the
same vector in the child frame).  The link's body is a capsule that starts at its joint
and runs ``length`` m along ``direction`` (link frame); its mass is a solid cylinder
(the seed's approximation) plus an optional point ``tip_mass`` at the distal end.
Links whose ``parent`` is ``None`` hang from the figure's base frame, which the
world placement moves.  A 2- or 3-DOF joint is a chain of links with zero length and
zero mass.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator


class FigureError(ValueError):
    """A figure description is invalid (message names the file, link and field)."""


class LinkSpec(BaseModel):
    """One link and the revolute joint that attaches it to its parent."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(description="Unique link/joint name.")
    parent: str | None = Field(default=None, description="Parent link name; None = base.")
    axis: tuple[float, float, float] = Field(description="Joint axis, parent frame (unitless).")
    offset: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description="Joint position in the parent link frame, m."
    )
    limits: tuple[float, float] = Field(
        default=(-np.inf, np.inf), description="Joint angle limits (min, max), rad."
    )
    friction: float = Field(
        default=1.0, ge=0.0, le=1.0, description="Velocity factor per frame: 0 locks, 1 free."
    )
    mass: float = Field(default=0.0, ge=0.0, description="Capsule (cylinder) mass, kg.")
    radius: float = Field(default=0.0, ge=0.0, description="Capsule radius, m.")
    length: float = Field(default=0.0, ge=0.0, description="Capsule axis length, m.")
    direction: tuple[float, float, float] | None = Field(
        default=None,
        description="Capsule direction in the link frame; default: towards the first child "
        "with a non-zero offset, else the parent's direction.",
    )
    tip_mass: float = Field(default=0.0, ge=0.0, description="Point mass at the distal end, kg.")

    @field_validator("axis")
    @classmethod
    def _unit_axis(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        n = float(np.linalg.norm(v))
        if n < 1e-12:
            raise ValueError("axis must be a non-zero 3-vector")
        return (v[0] / n, v[1] / n, v[2] / n)

    @field_validator("limits")
    @classmethod
    def _ordered(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not v[0] <= v[1]:
            raise ValueError(f"limits must satisfy min <= max, got {v}")
        return v


class FigureSpec(BaseModel):
    """File schema: ``name`` plus a list of ``links`` (parents listed before children)."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(default="figure", description="Figure name.")
    links: list[LinkSpec] = Field(min_length=1, description="Links in topological order.")


@dataclass(frozen=True)
class Figure:
    """Immutable array form of a figure (n links = n joints = n DOF).

    Attributes (all SI): ``parent`` (n,) int (-1 = base); ``axis`` (n, 3); ``offset``
    (n, 3) m; ``lower``/``upper`` (n,) rad; ``friction`` (n,); ``mass`` (n,) kg (capsule
    plus tip); ``com`` (n, 3) m and ``inertia`` (n, 3, 3) kg m^2 about the COM, link
    frame; ``radius`` (n,) m; ``length`` (n,) m; ``direction`` (n, 3) unit, link frame.
    """

    name: str
    joint_names: tuple[str, ...]
    parent: np.ndarray
    axis: np.ndarray
    offset: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    friction: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray
    radius: np.ndarray
    length: np.ndarray
    direction: np.ndarray

    @property
    def n_dof(self) -> int:
        """Number of joints (= links = degrees of freedom)."""
        return len(self.joint_names)

    @cached_property
    def tips(self) -> np.ndarray:
        """Distal capsule end of every link, (n, 3) m in the link frame."""
        return np.ascontiguousarray(self.length[:, None] * self.direction)

    @cached_property
    def packed(self) -> np.ndarray:
        """Per-link constants in one (n, 22) array for the compiled kernels: axis, offset,
        mass, COM, inertia (row-major) and tip (layout in ``physanim.dynamics.kernels``)."""
        return np.ascontiguousarray(
            np.concatenate(
                [
                    self.axis,
                    self.offset,
                    self.mass[:, None],
                    self.com,
                    self.inertia.reshape(-1, 9),
                    self.tips,
                ],
                axis=1,
            )
        )

    @property
    def total_mass(self) -> float:
        """Total mass, kg."""
        return float(self.mass.sum())

    def index(self, name: str) -> int:
        """Index of joint ``name``; raises ``KeyError`` listing the known names."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise KeyError(
                f"figure {self.name!r} has no joint {name!r}; known: {', '.join(self.joint_names)}"
            ) from None

    def subtree(self, name: str) -> np.ndarray:
        """Boolean mask (n,) of joint ``name`` and all its descendants."""
        mask = np.zeros(self.n_dof, dtype=bool)
        mask[self.index(name)] = True
        for i in range(self.n_dof):  # parents precede children
            if self.parent[i] >= 0 and mask[self.parent[i]]:
                mask[i] = True
        return mask

    @classmethod
    def from_dict(cls, d: dict[str, Any], *, source: str = "<dict>") -> Figure:
        """Build from the YAML schema (see :class:`FigureSpec`); ``source`` names errors."""
        try:
            spec = FigureSpec.model_validate(d)
        except ValidationError as e:
            raise FigureError(f"{source}: invalid figure description:\n{e}") from None
        return _build(spec, source)

    @classmethod
    def from_yaml(cls, path: str | Path) -> Figure:
        """Load a figure YAML file."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"figure file {path} does not exist")
        with path.open() as f:
            d = yaml.safe_load(f)
        if not isinstance(d, dict):
            raise FigureError(f"{path}: expected a mapping with 'links', got {type(d).__name__}")
        return cls.from_dict(d, source=str(path))


def cylinder_inertia(
    mass: float, radius: float, length: float, direction: np.ndarray
) -> np.ndarray:
    """Inertia (3, 3) kg m^2 of a solid cylinder about its centre, axis ``direction``."""
    axial = 0.5 * mass * radius**2
    transverse = mass * (3.0 * radius**2 + length**2) / 12.0
    dd = np.outer(direction, direction)
    return transverse * (np.eye(3) - dd) + axial * dd


def _point_inertia(mass: float, r: np.ndarray) -> np.ndarray:
    """Inertia (3, 3) of a point mass at offset ``r`` (3,) m (parallel-axis term)."""
    return mass * (float(r @ r) * np.eye(3) - np.outer(r, r))


def _build(spec: FigureSpec, source: str) -> Figure:
    names = [link.name for link in spec.links]
    index: dict[str, int] = {}
    parent = np.full(len(names), -1, dtype=np.int64)
    for i, link in enumerate(spec.links):
        if link.name in index:
            raise FigureError(f"{source}: link {link.name!r} is declared twice")
        if link.parent is not None:
            if link.parent not in index:
                raise FigureError(
                    f"{source}: link {link.name!r} has parent {link.parent!r}, which is not "
                    "declared before it (list parents first)"
                )
            parent[i] = index[link.parent]
        index[link.name] = i

    n = len(names)
    offset = np.array([link.offset for link in spec.links], dtype=float)
    direction = np.zeros((n, 3))
    for i in reversed(range(n)):  # explicit or first child with non-zero offset
        link = spec.links[i]
        if link.direction is not None:
            v = np.asarray(link.direction, dtype=float)
            if np.linalg.norm(v) < 1e-12:
                raise FigureError(f"{source}: link {link.name!r} has a zero direction")
            direction[i] = v / np.linalg.norm(v)
            continue
        children = [j for j in range(i + 1, n) if parent[j] == i and np.linalg.norm(offset[j]) > 0]
        if children:
            direction[i] = offset[children[0]] / np.linalg.norm(offset[children[0]])
    for i in range(n):  # inherit the parent's direction where still unset
        if np.linalg.norm(direction[i]) == 0.0:
            direction[i] = direction[parent[i]] if parent[i] >= 0 else (0.0, -1.0, 0.0)

    mass = np.zeros(n)
    com = np.zeros((n, 3))
    inertia = np.zeros((n, 3, 3))
    for i, link in enumerate(spec.links):
        d = direction[i]
        c_cyl = 0.5 * link.length * d
        tip = link.length * d
        m = link.mass + link.tip_mass
        c = (link.mass * c_cyl + link.tip_mass * tip) / m if m > 0 else np.zeros(3)
        inertia[i] = (
            cylinder_inertia(link.mass, link.radius, link.length, d)
            + _point_inertia(link.mass, c_cyl - c)
            + _point_inertia(link.tip_mass, tip - c)
        )
        mass[i], com[i] = m, c

    return Figure(
        name=spec.name,
        joint_names=tuple(names),
        parent=parent,
        axis=np.array([link.axis for link in spec.links], dtype=float),
        offset=offset,
        lower=np.array([link.limits[0] for link in spec.links], dtype=float),
        upper=np.array([link.limits[1] for link in spec.links], dtype=float),
        friction=np.array([link.friction for link in spec.links], dtype=float),
        mass=mass,
        com=com,
        inertia=inertia,
        radius=np.array([link.radius for link in spec.links], dtype=float),
        length=np.array([link.length for link in spec.links], dtype=float),
        direction=direction,
    )
