"""Planar arm kinematics and straight-line muscle paths (seed 000 sections 3.1-3.3).

Bodies are numbered 0 (the fixed base, whose frame is the world frame with origin at joint 0)
and i + 1 for link i.  Joint j turns body j + 1 relative to body j about +z, so a body b lies
distal of joint j when b > j.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from physanim.dynamics import Figure, capsule_segments, forward_kinematics
from physanim.muscle.params import ArmParams


def arm_figure(arm: ArmParams) -> Figure:
    """The arm as a dynamics figure: a serial chain of z-axis revolute joints, links along +x.

    Each link is a solid cylinder (mass, radius, length); ``arm.load_mass`` is a point mass at
    the distal end of the last link (the hand).
    """
    links = []
    for i, link in enumerate(arm.links):
        links.append(
            {
                "name": link.name,
                "parent": arm.links[i - 1].name if i else None,
                "axis": (0.0, 0.0, 1.0),
                "offset": (arm.links[i - 1].length if i else 0.0, 0.0, 0.0),
                "limits": (np.radians(link.joint_min_deg), np.radians(link.joint_max_deg)),
                "mass": link.mass,
                "radius": link.radius,
                "length": link.length,
                "direction": (1.0, 0.0, 0.0),
                "tip_mass": arm.load_mass if i == len(arm.links) - 1 else 0.0,
            }
        )
    return Figure.from_dict({"name": "arm", "links": links}, source="ArmParams")


def body_frames(fig: Figure, q: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Planar origins and rotations of all bodies, base first, for joint angles q (T, n) rad.

    Forward kinematics p_{i+1} = p_i + l_i Rot(e_z, theta_0 + ... + theta_i) e_x (seed section
    3.1) by the dynamics package.  Returns origins (T, n + 2, 2) m (the base, joints 0..n-1 and
    the hand) and rotations (T, n + 2, 2, 2) (the base is the identity; the hand takes the last
    link's).
    """
    kin = forward_kinematics(fig, np.atleast_2d(np.asarray(q, dtype=float)))
    _, end = capsule_segments(fig, kin)
    t = kin.positions.shape[0]
    origins = np.concatenate([np.zeros((t, 1, 2)), kin.positions[..., :2], end[:, -1:, :2]], axis=1)
    rot = kin.rotations[..., :2, :2]
    base = np.broadcast_to(np.eye(2), (t, 1, 2, 2))
    return origins, np.concatenate([base, rot, rot[:, -1:]], axis=1)


@dataclass(frozen=True)
class MusclePaths:
    """Straight-line muscle geometry over time (T samples, m muscles, n joints).

    origin, insertion: (T, m, 2) world points, m.  length: (T, m) musculotendon length, m.
    direction: (T, m, 2) unit line of action, from the insertion towards the origin.
    moment_arm: (T, m, n) joint torque per newton of muscle tension, m (N m / N), the seed's
    (c x F) / |F| summed over the muscle's two attachment forces; positive flexes the joint.
    """

    origin: NDArray[np.float64]
    insertion: NDArray[np.float64]
    length: NDArray[np.float64]
    direction: NDArray[np.float64]
    moment_arm: NDArray[np.float64]


def _cross2(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def muscle_paths(arm: ArmParams, q: ArrayLike) -> MusclePaths:
    """Attachment points, lengths, lines of action and moment arms for joint angles q (T, n) rad."""
    fig = arm_figure(arm)
    origins, rotations = body_frames(fig, q)
    o_body = np.array([arm.body_index(m.origin_body) for m in arm.muscles])
    i_body = np.array([arm.body_index(m.insertion_body) for m in arm.muscles])
    o_local = np.array([m.origin for m in arm.muscles], dtype=float)
    i_local = np.array([m.insertion for m in arm.muscles], dtype=float)

    def world(body: NDArray[np.int_], local: NDArray[np.float64]) -> NDArray[np.float64]:
        return origins[:, body] + np.einsum("tmij,mj->tmi", rotations[:, body], local)

    p_o, p_i = world(o_body, o_local), world(i_body, i_local)
    span = p_o - p_i
    length = np.linalg.norm(span, axis=-1)
    if np.any(length < 1e-9):
        bad = np.unique(np.nonzero(length < 1e-9)[1])
        raise ValueError(
            f"muscles {[arm.muscles[k].name for k in bad]} have coincident origin and insertion "
            "at some joint angles; move their attachment points apart"
        )
    u = span / length[..., None]
    joints = origins[:, 1 : fig.n_dof + 1]  # (T, n, 2)
    n_j = np.arange(fig.n_dof)
    ins_distal = (i_body[:, None] > n_j[None, :]).astype(float)  # (m, n)
    org_distal = (o_body[:, None] > n_j[None, :]).astype(float)
    arm_i = _cross2(p_i[:, :, None, :] - joints[:, None], u[:, :, None, :])  # (T, m, n)
    arm_o = _cross2(p_o[:, :, None, :] - joints[:, None], -u[:, :, None, :])
    moment_arm = ins_distal * arm_i + org_distal * arm_o
    return MusclePaths(p_o, p_i, length, u, moment_arm)
