"""Forward/inverse dynamics and the inertia matrix against Pinocchio and MuJoCo (the
``refs`` extra, installed by ``make setup``)."""

import dataclasses

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from physanim.dynamics import forward_dynamics, inverse_dynamics, mass_matrix
from physanim.dynamics.reference_models import (
    mujoco_model,
    pinocchio_forces,
    pinocchio_model,
)


def _full(upper):
    """Pinocchio's CRBA fills the upper triangle; the symmetric matrix."""
    upper = np.triu(upper)
    return upper + np.triu(upper, 1).T


def _states(fig, count, seed):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield (
            rng.uniform(-1.5, 1.5, fig.n_dof),
            rng.normal(size=fig.n_dof),
            rng.normal(size=fig.n_dof),
        )


@pytest.mark.parametrize("name", ["arm2", "human"])
def test_against_pinocchio(name, request):
    fig = request.getfixturevalue(name)
    model = pinocchio_model(fig)
    data = model.createData()
    for q, qd, x in _states(fig, 10, 11):
        ref = pin.aba(model, data, q, qd, x)
        for method in ("aba", "crba", "rnea"):
            np.testing.assert_allclose(
                forward_dynamics(fig, q, qd, x, method=method), ref, rtol=0, atol=1e-9
            )
        np.testing.assert_allclose(mass_matrix(fig, q), _full(pin.crba(model, data, q)), atol=1e-12)
        np.testing.assert_allclose(
            inverse_dynamics(fig, q, qd, x), pin.rnea(model, data, q, qd, x), atol=1e-10
        )


def test_external_tip_loads_against_pinocchio(human):
    model = pinocchio_model(human)
    data = model.createData()
    rng = np.random.default_rng(12)
    names = ["r_wrist", "l_ankle_z", "lumbar_z"]
    for q, qd, tau in _states(human, 5, 13):
        ext = np.zeros((human.n_dof, 6))
        for name in names:
            ext[human.index(name)] = rng.normal(size=6)
        loads = {name: ext[human.index(name)] for name in names}
        ref = pin.aba(model, data, q, qd, tau, pinocchio_forces(human, q, ext))
        got = forward_dynamics(human, q, qd, tau, ext_forces=loads)
        np.testing.assert_allclose(got, ref, atol=1e-9)
        np.testing.assert_allclose(
            forward_dynamics(human, q, qd, tau, ext_forces=loads, method="crba"), ref, atol=1e-9
        )


@pytest.mark.parametrize("name", ["arm2", "human"])
def test_against_mujoco(name, request):
    fig = request.getfixturevalue(name)
    model = mujoco_model(fig)
    data = mujoco.MjData(model)
    assert [model.joint(j).name for j in range(model.njnt)] == list(fig.joint_names)
    full = np.zeros((fig.n_dof, fig.n_dof))
    for q, qd, tau in _states(fig, 10, 14):
        data.qpos[:], data.qvel[:], data.qfrc_applied[:] = q, qd, tau
        mujoco.mj_forward(model, data)
        np.testing.assert_allclose(forward_dynamics(fig, q, qd, tau), data.qacc, atol=1e-9)
        mujoco.mj_fullM(model, data, full)
        np.testing.assert_allclose(mass_matrix(fig, q), full, atol=1e-12)


def test_crba_counts_massless_links_with_inertia(arm2):
    """A link with zero mass but rotational inertia 0.01 I: H[1, 1] = 0.01 kg m^2."""
    inertia = arm2.inertia.copy()
    inertia[1] = 0.01 * np.eye(3)
    fig = dataclasses.replace(arm2, mass=np.array([arm2.mass[0], 0.0]), inertia=inertia)
    data = (model := pinocchio_model(fig)).createData()
    for q, qd, tau in _states(fig, 5, 15):
        h = mass_matrix(fig, q)
        assert h[1, 1] == pytest.approx(0.01, abs=1e-15)
        np.testing.assert_allclose(h, mass_matrix(fig, q, method="rnea"), atol=1e-15)
        np.testing.assert_allclose(h, _full(pin.crba(model, data, q)), atol=1e-15)
        np.testing.assert_allclose(
            forward_dynamics(fig, q, qd, tau), pin.aba(model, data, q, qd, tau), atol=1e-10
        )
