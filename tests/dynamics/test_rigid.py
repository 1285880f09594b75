import dataclasses

import numpy as np
import pytest

from physanim.dynamics import (
    Figure,
    FigureError,
    forward_dynamics,
    inverse_dynamics,
    mass_matrix,
    mechanical_energy,
    passive_step,
    simulate_passive,
)

G = 9.81


def _random_state(fig, rng):
    lo = np.where(np.isfinite(fig.lower), fig.lower, -np.pi)
    hi = np.where(np.isfinite(fig.upper), fig.upper, np.pi)
    return rng.uniform(lo, hi), rng.normal(size=fig.n_dof), rng.normal(size=fig.n_dof)


@pytest.mark.parametrize("name", ["arm2", "human"])
@pytest.mark.parametrize("method", ["aba", "crba", "rnea"])
def test_forward_inverts_inverse(name, method, request):
    fig = request.getfixturevalue(name)
    rng = np.random.default_rng(1)
    load = {fig.joint_names[-1]: rng.normal(size=6)}
    for _ in range(10):
        q, qd, qdd = _random_state(fig, rng)
        kw = dict(base_acc=rng.normal(size=3), ext_forces=load)
        tau = inverse_dynamics(fig, q, qd, qdd, **kw)
        np.testing.assert_allclose(
            forward_dynamics(fig, q, qd, tau, method=method, **kw), qdd, rtol=0, atol=1e-10
        )


@pytest.mark.parametrize("name", ["arm2", "human"])
def test_mass_matrix_spd_and_seed_method_equals_crba(name, request):
    fig = request.getfixturevalue(name)
    rng = np.random.default_rng(2)
    for _ in range(10):
        q, _, _ = _random_state(fig, rng)
        h = mass_matrix(fig, q, method="crba")
        np.testing.assert_allclose(mass_matrix(fig, q, method="rnea"), h, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(h, h.T)
        assert np.linalg.eigvalsh(h).min() > 0


def test_batched_inverse_dynamics_matches_single(human):
    rng = np.random.default_rng(3)
    q, qd, qdd = (rng.normal(size=(5, human.n_dof)) for _ in range(3))
    tau = inverse_dynamics(human, q, qd, qdd)
    for t in range(5):
        np.testing.assert_allclose(tau[t], inverse_dynamics(human, q[t], qd[t], qdd[t]), atol=1e-12)


def test_double_pendulum_matches_lagrangian(arm2):
    """Hand-derived Lagrangian of a planar 2-link pendulum with distributed masses."""
    m1, l1, r1 = 2.0, 0.30, 0.045
    mc, l2, r2, mt = 1.5, 0.28, 0.04, 0.5  # cylinder + tip mass of link 2
    lc1, i1 = l1 / 2, m1 * (3 * r1**2 + l1**2) / 12
    m2 = mc + mt
    lc2 = (mc * l2 / 2 + mt * l2) / m2
    i2 = mc * (3 * r2**2 + l2**2) / 12 + mc * (l2 / 2 - lc2) ** 2 + mt * (l2 - lc2) ** 2
    rng = np.random.default_rng(4)
    for _ in range(20):
        (a, b), (da, db), (dda, ddb) = rng.normal(size=(3, 2))
        c, h = np.cos(b), m2 * l1 * lc2 * np.sin(b)
        m11 = i1 + i2 + m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * c)
        m12 = i2 + m2 * (lc2**2 + l1 * lc2 * c)
        m22 = i2 + m2 * lc2**2
        g1 = G * (m1 * lc1 * np.sin(a) + m2 * (l1 * np.sin(a) + lc2 * np.sin(a + b)))
        g2 = G * m2 * lc2 * np.sin(a + b)
        tau = np.array(
            [
                m11 * dda + m12 * ddb - h * (2 * da * db + db**2) + g1,
                m12 * dda + m22 * ddb + h * da**2 + g2,
            ]
        )
        got = inverse_dynamics(arm2, [a, b], [da, db], [dda, ddb], gravity=(0, -G, 0))
        np.testing.assert_allclose(got, tau, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(
            mass_matrix(arm2, [a, b]), [[m11, m12], [m12, m22]], rtol=1e-12, atol=1e-14
        )


def test_tip_mass_equals_external_force_at_tip(arm2):
    """A tip mass m at rest weighs like an external force m g down at the link's tip."""
    d = {
        "name": "arm",
        "links": [
            {
                "name": "shoulder",
                "axis": [0, 0, 1],
                "mass": 2.0,
                "radius": 0.045,
                "length": 0.3,
                "direction": [0, -1, 0],
            },
            {
                "name": "elbow",
                "parent": "shoulder",
                "axis": [0, 0, 1],
                "offset": [0, -0.3, 0],
                "mass": 1.5,
                "radius": 0.04,
                "length": 0.28,
                "direction": [0, -1, 0],
            },
        ],
    }
    bare = Figure.from_dict(d)
    q = np.array([0.7, 0.4])
    with_tip = inverse_dynamics(arm2, q, [0, 0], [0, 0])
    with_force = inverse_dynamics(
        bare, q, [0, 0], [0, 0], ext_forces={"elbow": [0, -0.5 * G, 0, 0, 0, 0]}
    )
    np.testing.assert_allclose(with_force, with_tip, atol=1e-12)


def test_energy_conserved_and_error_falls_with_dt(human):
    fig = dataclasses.replace(
        human, lower=np.full(30, -np.inf), upper=np.full(30, np.inf), friction=np.ones(30)
    )
    rng = np.random.default_rng(5)
    q0, qd0 = rng.uniform(-0.5, 0.5, 30), 0.5 * rng.normal(size=30)
    errors = []
    for dt in (2e-3, 1e-3):
        q, qd = simulate_passive(fig, q0, qd0, dt, round(0.3 / dt), gravity=(0, 0, 0))
        e = np.array(
            [mechanical_energy(fig, a, b, gravity=(0, 0, 0)) for a, b in zip(q, qd, strict=True)]
        )
        errors.append(np.abs(e / e[0] - 1).max())
    assert errors[0] < 0.05
    assert errors[1] < 0.6 * errors[0]  # first-order integrator: error ~ dt


def test_limits_never_exceeded(human):
    rng = np.random.default_rng(6)
    q0 = np.clip(rng.normal(size=30), human.lower, human.upper)
    q, _ = simulate_passive(human, q0, 3 * rng.normal(size=30), 1 / 300, 150)
    assert (q >= human.lower - 1e-12).all() and (q <= human.upper + 1e-12).all()
    at_limit = np.isclose(q, human.lower, atol=1e-12) | np.isclose(q, human.upper, atol=1e-12)
    assert at_limit.any()  # the run did hit limits


def test_clamped_acceleration_follows_eq7(arm2):
    """Elbow just below its upper limit with a large velocity is clamped exactly."""
    q, qd, dt = np.array([0.0, 2.55]), np.array([0.0, 10.0]), 0.01
    r = passive_step(arm2, q, qd, dt, friction=np.ones(2))
    assert r.clamped.tolist() == [False, True]
    assert r.q[1] == arm2.upper[1]
    assert r.qdd[1] == pytest.approx(((arm2.upper[1] - q[1]) / dt - qd[1]) / dt)
    # the free shoulder responds to the prescribed elbow acceleration (re-solved eq 2)
    h = mass_matrix(arm2, q)
    b = inverse_dynamics(arm2, q, qd, [0, 0])
    assert h[0] @ r.qdd + b[0] == pytest.approx(0.0, abs=1e-9)


def test_friction_zero_locks_and_one_is_free(arm2):
    q0, qd0 = np.array([0.5, 1.0]), np.array([1.0, -1.0])
    q, _ = simulate_passive(arm2, q0, qd0, 0.005, 100, friction=np.array([1.0, 0.0]))
    np.testing.assert_array_equal(q[:, 1], q0[1])
    assert np.ptp(q[:, 0]) > 0.1
    # friction 1 (and no limit hit): plain semi-implicit Euler on forward dynamics
    free = dataclasses.replace(arm2, lower=np.full(2, -np.inf), upper=np.full(2, np.inf))
    q, qd = simulate_passive(free, q0, qd0, 0.005, 50, friction=np.ones(2))
    qr, vr = q0.copy(), qd0.copy()
    for _ in range(50):
        vr = vr + 0.005 * forward_dynamics(free, qr, vr)
        qr = qr + 0.005 * vr
    np.testing.assert_allclose(q[-1], qr, atol=1e-12)


def test_figure_errors():
    with pytest.raises(FigureError, match="not declared before"):
        Figure.from_dict({"links": [{"name": "a", "parent": "b", "axis": [1, 0, 0]}]})
    with pytest.raises(FigureError, match="axis"):
        Figure.from_dict({"links": [{"name": "a", "axis": [0, 0, 0]}]})
    with pytest.raises(FileNotFoundError, match="nope.yaml"):
        Figure.from_yaml("nope.yaml")


def test_cylinder_inertia(human):
    i = human.index("r_hip_y")  # thigh: m 7, r 0.07, L 0.42 along -y
    m, r, length = 7.0, 0.07, 0.42
    np.testing.assert_allclose(
        np.diag(human.inertia[i]),
        [m * (3 * r**2 + length**2) / 12, m * r**2 / 2, m * (3 * r**2 + length**2) / 12],
    )
    assert human.n_dof == 30
    assert human.total_mass == pytest.approx(70.5)
