"""The arm's geometry and inverse dynamics against OpenSim (the ``refs`` extra): the same two
pin-jointed links and straight two-point muscle paths built as an OpenSim model."""

from __future__ import annotations

import numpy as np
import opensim as osim
import pytest

from physanim.dynamics import inverse_dynamics
from physanim.muscle.geometry import arm_figure, muscle_paths
from physanim.muscle.params import ArmParams


def _opensim_arm(arm: ArmParams, with_muscles: bool):
    """OpenSim model of ``arm``: bodies as in :func:`arm_figure` (inertia about the COM),
    PinJoints about +z at each link's proximal end, Thelen muscles on two-point paths."""
    fig = arm_figure(arm)
    model = osim.Model()
    model.setGravity(osim.Vec3(0.0, -9.81, 0.0))
    bodies = {arm.base_name: model.getGround()}
    parent, offset, joints = model.getGround(), 0.0, []
    for i, link in enumerate(arm.links):
        inertia = fig.inertia[i]
        body = osim.Body(
            link.name,
            float(fig.mass[i]),
            osim.Vec3(*fig.com[i]),
            osim.Inertia(*np.diag(inertia), inertia[0, 1], inertia[0, 2], inertia[1, 2]),
        )
        model.addBody(body)
        zero = osim.Vec3(0.0, 0.0, 0.0)
        joint = osim.PinJoint(f"J{i}", parent, osim.Vec3(offset, 0, 0), zero, body, zero, zero)
        model.addJoint(joint)
        joints.append(joint)
        bodies[link.name] = body
        parent, offset = body, link.length
    muscles = []
    for m in arm.muscles if with_muscles else []:
        unit = osim.Thelen2003Muscle(
            m.name,
            m.max_isometric_force,
            m.optimal_fibre_length,
            m.tendon_slack_length,
            np.radians(m.pennation_deg),
        )
        unit.addNewPathPoint("origin", bodies[m.origin_body], osim.Vec3(*m.origin, 0.0))
        unit.addNewPathPoint("insertion", bodies[m.insertion_body], osim.Vec3(*m.insertion, 0.0))
        model.addForce(unit)
        muscles.append(unit)
    return model, model.initSystem(), [j.getCoordinate() for j in joints], muscles


@pytest.mark.parametrize("load", [0.0, 1.0])
def test_muscle_lengths_and_moment_arms_match_opensim(load):
    arm = ArmParams(load_mass=load)
    model, state, coords, muscles = _opensim_arm(arm, with_muscles=True)
    q = np.random.default_rng(0).uniform([-1.2, 0.0], [1.2, 2.4], size=(8, 2))
    paths = muscle_paths(arm, q)
    for t in range(len(q)):
        for c, value in zip(coords, q[t], strict=True):
            c.setValue(state, float(value))
        model.realizePosition(state)
        length = [m.getLength(state) for m in muscles]
        moment = [[m.computeMomentArm(state, c) for c in coords] for m in muscles]
        np.testing.assert_allclose(paths.length[t], length, atol=1e-12)
        np.testing.assert_allclose(paths.moment_arm[t], moment, atol=1e-12)


def test_arm_inverse_dynamics_matches_opensim():
    arm = ArmParams(load_mass=0.0)
    model, state, coords, _ = _opensim_arm(arm, with_muscles=False)
    solver = osim.InverseDynamicsSolver(model)
    rng = np.random.default_rng(1)
    fig = arm_figure(arm)
    for _ in range(5):
        q, qd, qdd = rng.uniform(-1, 1, 2), rng.normal(size=2), rng.normal(size=2)
        for c, a, v in zip(coords, q, qd, strict=True):
            c.setValue(state, float(a))
            c.setSpeedValue(state, float(v))
        model.realizeVelocity(state)
        udot = osim.Vector(2, 0.0)
        udot.set(0, float(qdd[0]))
        udot.set(1, float(qdd[1]))
        tau = solver.solve(state, udot)
        ref = [tau.get(0), tau.get(1)]
        np.testing.assert_allclose(inverse_dynamics(fig, q, qd, qdd), ref, atol=1e-10)
