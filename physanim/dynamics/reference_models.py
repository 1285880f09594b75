"""The same figure in independent rigid-body libraries (Pinocchio, MuJoCo), for tests and
benchmarks.  Both packages are the optional ``refs`` extra; they are imported on call.

Frames match :class:`physanim.dynamics.figure.Figure`: a joint sits at its link's offset in
the parent frame and turns about its axis; inertias are about the COM in the link frame;
gravity -9.81 m/s^2 along y.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from physanim.dynamics.figure import Figure
from physanim.dynamics.rigid import GRAVITY


def pinocchio_model(fig: Figure) -> Any:
    """A ``pinocchio.Model`` with one unaligned revolute joint per link, in figure order."""
    import pinocchio as pin

    model = pin.Model()
    ids: list[int] = []
    for i, name in enumerate(fig.joint_names):
        parent = 0 if fig.parent[i] < 0 else ids[fig.parent[i]]
        placement = pin.SE3(np.eye(3), fig.offset[i].copy())
        joint = pin.JointModelRevoluteUnaligned(fig.axis[i].copy())
        jid = model.addJoint(parent, joint, placement, name)
        inertia = pin.Inertia(float(fig.mass[i]), fig.com[i].copy(), fig.inertia[i].copy())
        model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        ids.append(jid)
    model.gravity.linear = np.asarray(GRAVITY, dtype=float)
    return model


def pinocchio_forces(fig: Figure, q: np.ndarray, ext: np.ndarray) -> list[Any]:
    """Per-joint ``pinocchio.Force`` (local frames) of tip loads ``ext`` (n, 6) [force N,
    moment N m] on world axes at pose q (n,) rad, the convention of ``ext_forces``."""
    import pinocchio as pin

    from physanim.dynamics.kinematics import forward_kinematics

    kin = forward_kinematics(fig, q)
    forces = [pin.Force.Zero()]
    for i in range(fig.n_dof):
        r = kin.rotations[i]
        f, m = ext[i, :3], ext[i, 3:]
        moment = m + np.cross(r @ fig.tips[i], f)  # about the joint origin
        forces.append(pin.Force(r.T @ f, r.T @ moment))
    return forces


def mujoco_xml(fig: Figure) -> str:
    """MJCF of the figure.  MuJoCo needs mass on every moving body, so a chain of massless
    links with zero offsets (a 2- or 3-DOF joint) becomes one body with several hinges,
    which MuJoCo applies in order like the chain."""

    def fmt(v: np.ndarray) -> str:
        return " ".join(f"{x:.17g}" for x in v)

    children: dict[int, list[int]] = {i: [] for i in range(-1, fig.n_dof)}
    for i, p in enumerate(fig.parent):
        children[int(p)].append(i)

    def body(first: int) -> str:
        chain, i = [first], first
        while fig.mass[i] == 0 and not fig.inertia[i].any():
            kids = children[i]
            if len(kids) != 1 or fig.offset[kids[0]].any():
                raise ValueError(
                    f"mujoco_xml: massless link {fig.joint_names[i]!r} must have exactly one "
                    "child at zero offset"
                )
            i = kids[0]
            chain.append(i)
        inertia = fig.inertia[i]
        full = [inertia[0, 0], inertia[1, 1], inertia[2, 2]]
        full += [inertia[0, 1], inertia[0, 2], inertia[1, 2]]
        joints = "".join(
            f'<joint name="{fig.joint_names[j]}" type="hinge" axis="{fmt(fig.axis[j])}"/>'
            for j in chain
        )
        inner = "".join(body(k) for k in children[i])
        return (
            f'<body pos="{fmt(fig.offset[first])}">{joints}'
            f'<inertial pos="{fmt(fig.com[i])}" mass="{fig.mass[i]:.17g}" '
            f'fullinertia="{fmt(np.array(full))}"/>{inner}</body>'
        )

    bodies = "".join(body(k) for k in children[-1])
    return (
        '<mujoco><compiler angle="radian" inertiafromgeom="false" balanceinertia="false" '
        f'boundmass="0" boundinertia="0"/><option gravity="{fmt(np.asarray(GRAVITY))}"/>'
        f"<worldbody>{bodies}</worldbody></mujoco>"
    )


def mujoco_model(fig: Figure) -> Any:
    """A compiled ``mujoco.MjModel`` of :func:`mujoco_xml`; its joints are in figure order."""
    import mujoco

    return mujoco.MjModel.from_xml_string(mujoco_xml(fig))
