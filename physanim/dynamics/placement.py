"""Placing an animated figure in the world (seed 001 section 3).

Two constraints govern the base position frame by frame: ``pin`` keeps one joint fixed
in the world; ``gravity`` moves the centre of mass ballistically and handles contact:
touching -> still touching pins the designated joint; touching -> free takes off; free
-> penetrating slides the COM back along its path to the first touching position and
pins the designated joint (or the joint nearest the contact) from then on.  A root path
(seed 002) instead prescribes the base position over a run of frames, optionally lifted
onto the ground so that the lowest capsule touches it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from physanim.dynamics.contact import Environment, environment_distance
from physanim.dynamics.figure import Figure
from physanim.dynamics.kinematics import capsule_segments, center_of_mass, forward_kinematics
from physanim.dynamics.params import KeyframeParams


@dataclass(frozen=True)
class WorldConstraint:
    """Constraint for the steps from frame f to f + 1, first_frame <= f < last_frame.

    ``joint``: index of the joint to pin (required for ``pin``; for ``gravity`` -1 means
    the joint nearest the contact).
    """

    kind: Literal["pin", "gravity"]
    first_frame: int
    last_frame: int
    joint: int = -1


@dataclass(frozen=True)
class RootPath:
    """Base positions ``positions`` (k, 3) m for frames first_frame .. first_frame + k - 1;
    ``on_ground``: move each frame's base along "up" until the figure's lowest capsule
    touches the environment (the positions' heights are then ignored)."""

    first_frame: int
    positions: np.ndarray
    on_ground: bool = True

    def covers(self, frame: int) -> bool:
        """Whether ``frame`` lies on the path."""
        return self.first_frame <= frame < self.first_frame + len(self.positions)


@dataclass(frozen=True)
class Placement:
    """Per-frame world placement: ``base_pos`` (F, 3) m, ``com`` (F, 3) m, ``contact``
    (F,) bool, ``pinned`` (F,) joint index (-1 none) and ``distance`` (F,) m, the
    smallest signed capsule-environment distance (negative = penetration)."""

    base_pos: np.ndarray
    com: np.ndarray
    contact: np.ndarray
    pinned: np.ndarray
    distance: np.ndarray


def place_in_world(
    fig: Figure,
    q: np.ndarray,
    fps: float,
    env: Environment,
    constraints: list[WorldConstraint],
    *,
    start_position: np.ndarray,
    start_joint: int = -1,
    gravity: np.ndarray | tuple[float, float, float] = (0.0, -9.81, 0.0),
    root_path: RootPath | None = None,
    params: KeyframeParams | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Placement:
    """Base positions for joint angles q (F, n) rad sampled at ``fps`` frames/s.

    Frame 0 puts joint ``start_joint`` (or the base, if -1) at ``start_position`` (3,) m,
    unless ``root_path`` covers it.  Frames on the root path take its positions (no
    constraint may act there); other steps without a constraint keep the base where it is.
    """
    params = params or KeyframeParams()
    tol = params.contact_tolerance
    g = np.asarray(gravity, dtype=float)
    dt = 1.0 / fps
    nf = len(q)
    kin = forward_kinematics(fig, q)
    rel = kin.positions  # (F, n, 3) joint positions with the base at the origin
    seg_a, seg_b = capsule_segments(fig, kin)
    solid = (fig.radius > 0) | (fig.length > 0)
    seg_a, seg_b, radius = seg_a[:, solid], seg_b[:, solid], fig.radius[solid]
    com_rel = center_of_mass(fig, kin)

    def gap(f: int, base: np.ndarray) -> tuple[float, np.ndarray]:
        return environment_distance(env, seg_a[f] + base, seg_b[f] + base, radius)

    def on_path(f: int, path: RootPath) -> np.ndarray:
        p = np.asarray(path.positions[f - path.first_frame], float)
        return p - gap(f, p)[0] * _up_of(g) if path.on_ground else p

    base = np.zeros((nf, 3))
    base[0] = np.asarray(start_position, float) - (rel[0, start_joint] if start_joint >= 0 else 0)
    if root_path is not None and root_path.covers(0):
        base[0] = on_path(0, root_path)
    contact = np.zeros(nf, dtype=bool)
    pinned = np.full(nf, -1)
    distance = np.zeros(nf)
    distance[0], _ = gap(0, base[0])
    contact[0] = distance[0] <= tol
    active: WorldConstraint | None = None
    pin_point = np.zeros(3)
    vel = np.zeros(3)  # COM velocity, m/s
    for c in range(nf - 1):
        d = c + 1
        cons = next((k for k in reversed(constraints) if k.first_frame <= c < k.last_frame), None)
        if cons is not active:  # entering a constraint: set up its pinned joint
            active = cons
            contact[c] = distance[c] <= tol
            if cons is not None and (cons.kind == "pin" or contact[c]):
                joint = cons.joint
                if joint < 0:
                    _, point = gap(c, base[c])
                    joint = _nearest_joint(rel[c] + base[c], point)
                pinned[c] = joint
                pin_point = base[c] + rel[c, joint]
        if root_path is not None and root_path.covers(d):
            base[d] = on_path(d, root_path)
        elif cons is None:
            base[d] = base[c]
        elif cons.kind == "pin":
            pinned[d] = pinned[c]
            base[d] = pin_point - rel[d, pinned[c]]
        else:
            base[d], contact[d], pinned[d], pin_point = _gravity_step(
                c,
                base[c],
                contact[c],
                pinned[c],
                pin_point,
                vel,
                cons.joint,
                com_rel,
                rel,
                g,
                dt,
                tol,
                params.backoff_iterations,
                gap,
            )
        distance[d], _ = gap(d, base[d])
        if cons is not None and cons.kind == "gravity" and not contact[d]:
            vel = vel + g * dt  # exact parabola in flight
        else:
            vel = (base[d] + com_rel[d] - base[c] - com_rel[c]) / dt
        if cons is None or cons.kind == "pin":
            contact[d] = distance[d] <= tol
        if progress is not None:
            progress(d, nf - 1)
    return Placement(base, base + com_rel, contact, pinned, distance)


def _nearest_joint(joints: np.ndarray, point: np.ndarray) -> int:
    return int(np.argmin(np.linalg.norm(joints - point, axis=1)))


def _gravity_step(
    c: int,
    base_c: np.ndarray,
    touching: bool,
    pin_joint: int,
    pin_point: np.ndarray,
    vel: np.ndarray,
    designated: int,
    com_rel: np.ndarray,
    rel: np.ndarray,
    g: np.ndarray,
    dt: float,
    tol: float,
    iters: int,
    gap: Callable[[int, np.ndarray], tuple[float, np.ndarray]],
) -> tuple[np.ndarray, bool, int, np.ndarray]:
    """One step of seed 001 section 3.2; returns base_d, touching_d, pinned joint, pin point."""
    d = c + 1
    com_c = base_c + com_rel[c]
    com_t = com_c + vel * dt + 0.5 * g * dt**2  # (2) ballistic trial
    base_t = com_t - com_rel[d]
    dist_t, point = gap(d, base_t)
    if dist_t > tol:  # (4), (5): free at t_d
        return base_t, False, -1, pin_point
    if touching:  # (3): keep the pinned joint fixed; slide it along "up" to stay touching
        base_d = pin_point - rel[d, pin_joint]
        base_d = base_d - gap(d, base_d)[0] * _up_of(g)
        return base_d, True, pin_joint, base_d + rel[d, pin_joint]
    # (6): free -> penetrating: back off along the COM path to the first touching position
    lo, hi = 0.0, 1.0
    base_0 = com_c - com_rel[d]
    dist_0, point = gap(d, base_0)
    if dist_0 <= tol:  # already touching with the new pose: lift out of penetration
        base_d = base_0 - min(dist_0, 0.0) * _up_of(g)
    else:
        for _ in range(iters):
            mid = 0.5 * (lo + hi)
            if gap(d, base_0 + mid * (base_t - base_0))[0] > 0.0:
                lo = mid
            else:
                hi = mid
        base_d = base_0 + hi * (base_t - base_0)
        _, point = gap(d, base_d)
    joint = designated if designated >= 0 else _nearest_joint(rel[d] + base_d, point)
    return base_d, True, joint, base_d + rel[d, joint]


def _up_of(g: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(g)
    return -g / n if n > 0 else np.array([0.0, 1.0, 0.0])
