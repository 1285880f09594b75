"""Muscle-driven arm (issue 9): curves, geometry, force sharing, activations, shapes, configs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq, minimize

from flows.dags import ARM
from physanim.config import load_config
from physanim.dynamics import inverse_dynamics
from physanim.muscle import curves
from physanim.muscle.activation import MuscleConstants, fibre_state, tendon_force_at
from physanim.muscle.arm import solve_arm, torque_shortfalls
from physanim.muscle.geometry import arm_figure, muscle_paths
from physanim.muscle.params import ArmParams, ArmStudyParams, ModelParams
from physanim.muscle.shape import (
    activation_colour,
    mesh_volume,
    spindle_mesh,
    spindle_semi_axes,
    spindle_volume,
)
from physanim.muscle.sharing import box_qp, static_optimisation
from physanim.muscle.trajectory import seed_trajectory


def study(condition: str, **model) -> ArmStudyParams:
    cfg, _ = load_config(ARM.config_model(), [ARM.default_config])
    s = cfg.muscles.resolved()[condition]
    return s.model_copy(update={"model": s.model.model_copy(update=model)})


@pytest.fixture(scope="module")
def results():
    return {
        (c, fs): solve_arm(study(c, force_sharing=fs))
        for c in ("free", "load_1kg", "tensed")
        for fs in ("seed_rule", "static_optimisation")
    }


def test_curves_reference_values():
    assert curves.fibre_force(1.0, 1.0, 0.0) == pytest.approx(1.0, abs=1e-15)
    assert curves.active_force_length(1.0) == 1.0  # eq 7 exceeds 1 there and is capped
    assert curves.passive_force_length([0.8, 1.0, 1.5]) == pytest.approx([0.0, 0.0, 1.0])
    assert curves.force_velocity([-1.5, -1.0, 0.0]) == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert curves.force_velocity(1e9) == pytest.approx(1.8, abs=0.01)  # eccentric plateau
    v = np.linspace(-1, 2, 400)
    assert np.all(np.diff(curves.force_velocity(v)) > 0)
    # independent of the activation-dependent v_max at a = 1 and at v = 0
    assert curves.fibre_force(1.0, 0.9, -0.3, 0.5) == curves.fibre_force(1.0, 0.9, -0.3, 1.0)
    assert curves.fibre_force(0.3, 0.9, 0.0, 0.5) == curves.fibre_force(0.3, 0.9, 0.0, 1.0)


def test_tendon_curve_and_inverse_round_trip():
    eps = np.linspace(0.0, 0.1, 1001)
    f = curves.tendon_force(eps)
    assert f[eps == 0.02] == pytest.approx(0.5)
    assert curves.tendon_force(0.1) == pytest.approx(3.5)
    assert curves.tendon_force(0.01) == pytest.approx(0.25)
    np.testing.assert_allclose(curves.tendon_strain(f), eps, atol=1e-15)
    forces = np.linspace(0.0, 3.5, 777)
    np.testing.assert_allclose(
        curves.tendon_force(curves.tendon_strain(forces)), forces, atol=1e-14
    )


def test_trajectory_rest_to_rest_and_derivatives():
    t = np.linspace(0, 2.0, 2001)
    q, qd, qdd = seed_trajectory(t, [0.3, -1.0], [1.2, 2.0], duration=2.0)
    np.testing.assert_allclose(q[0], [0.3, -1.0])
    np.testing.assert_allclose(q[-1], [1.5, 1.0])
    np.testing.assert_allclose(qd[[0, -1]], 0.0, atol=1e-12)
    np.testing.assert_allclose(qdd[[0, -1]], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.gradient(q, t, axis=0)[1:-1], qd[1:-1], atol=1e-5)
    np.testing.assert_allclose(np.gradient(qd, t, axis=0)[1:-1], qdd[1:-1], atol=1e-4)


def test_moment_arms_equal_minus_length_gradient():
    """Virtual work: the seed's c x F moment arm is -dl/dq (central differences)."""
    arm = ArmParams()
    rng = np.random.default_rng(0)
    q = rng.uniform([-1.2, 0.0], [1.2, 2.4], size=(50, 2))
    r = muscle_paths(arm, q).moment_arm
    h = 1e-6
    for j in range(2):
        dq = np.zeros(2)
        dq[j] = h
        dl = (muscle_paths(arm, q + dq).length - muscle_paths(arm, q - dq).length) / (2 * h)
        np.testing.assert_allclose(r[:, :, j], -dl, atol=1e-8)
    # flexors flex (R > 0) and extensors extend over the whole range of motion
    assert np.all(r[:, [0, 2], [0, 1]] > 0) and np.all(r[:, [1, 3], [0, 1]] < 0)


def test_fibre_state_constant_width_pennation():
    arm = ArmParams()
    mc = MuscleConstants.from_arm(arm)
    f0 = mc.max_isometric_force
    # at optimal fibre length the pennation is the configured one
    l_mt = mc.optimal_fibre_length * np.cos(np.radians(10.0)) + 1.05 * mc.tendon_slack_length
    st = fibre_state(l_mt[None], (f0 * curves.tendon_force(0.05))[None], mc)
    np.testing.assert_allclose(st.tendon_length[0], 1.05 * mc.tendon_slack_length)
    pennation = np.degrees(np.arccos(st.cos_pennation[0]))
    np.testing.assert_allclose(pennation[[0, 1, 3]], 10.0, atol=1e-9)
    np.testing.assert_allclose(
        st.fibre_length[0][[0, 1, 3]], mc.optimal_fibre_length[[0, 1, 3]], rtol=1e-12
    )


def test_box_qp_matches_kkt_and_bounds():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(300, 2, 4))
    b = np.einsum("tnm,tm->tn", a, rng.uniform(0, 1, size=(300, 4)))
    lo, hi = np.zeros((300, 4)), np.ones((300, 4))
    x, resid = box_qp(a, b, lo, hi)
    assert np.abs(resid).max() < 1e-9
    assert x.min() >= 0 and x.max() <= 1
    # KKT: x = clip(A^T lam) for some lam -> the free components lie in the row space of A
    for i in range(0, 300, 37):
        free = (x[i] > 1e-9) & (x[i] < 1 - 1e-9)
        if free.sum() > 2:
            coef, *_ = np.linalg.lstsq(a[i][:, free].T, x[i][free], rcond=None)
            np.testing.assert_allclose(a[i][:, free].T @ coef, x[i][free], atol=1e-8)


@pytest.mark.parametrize("condition", ["free", "load_1kg", "tensed"])
@pytest.mark.parametrize("sharing", ["seed_rule", "static_optimisation"])
def test_muscle_torques_reproduce_inverse_dynamics(results, condition, sharing):
    res = results[(condition, sharing)]
    s = study(condition, force_sharing=sharing)
    fig = arm_figure(s.arm)
    np.testing.assert_allclose(inverse_dynamics(fig, res.q, res.qd, res.qdd), res.torque)
    assert res.activation.min() >= 0 and res.activation.max() <= 1
    # forward check: the muscle model at the estimated activations gives back the torques
    mc = MuscleConstants.from_arm(s.arm)
    st = fibre_state(res.musculotendon_length, res.force, mc)
    delivered = tendon_force_at(res.activation, st, res.fibre_velocity, mc, s.model)
    torque = np.einsum("tmn,tm->tn", res.moment_arm, delivered)
    producible = np.all(res.shortfall == 0, axis=1)
    assert producible.all()  # the shipped conditions are within the muscles' capacity
    assert np.abs(torque - res.torque).max() < 1e-6
    assert np.abs(res.torque_residual).max() < 1e-6


def test_shortfall_reported_when_muscles_too_weak():
    s = study("load_1kg", force_sharing="seed_rule")
    weak = [
        m.model_copy(update={"max_isometric_force": 0.3 * m.max_isometric_force})
        for m in s.arm.muscles
    ]
    res = solve_arm(s.model_copy(update={"arm": s.arm.model_copy(update={"muscles": weak})}))
    assert res.activation.max() == 1.0
    assert res.shortfall.max() > 1.0  # N
    # the residual is exactly the torque of the missing force
    missing = np.einsum("tmn,tm->tn", res.moment_arm, res.shortfall)
    np.testing.assert_allclose(res.torque_residual, missing, atol=1e-9)
    assert np.abs(res.torque_residual).max() > 0.1


def test_physics_direction(results):
    free = results[("free", "seed_rule")].activation[:, 2]
    loaded = results[("load_1kg", "seed_rule")].activation[:, 2]
    assert loaded.max() > free.max() + 0.2  # elbow flexor works harder with 1 kg in the hand
    tensed = results[("tensed", "static_optimisation")].activation
    assert tensed.min() == pytest.approx(0.1, abs=1e-12)  # the floor holds on what is reported
    assert results[("tensed", "seed_rule")].activation.min() >= 0.1 - 1e-9  # fixed-point tol
    assert results[("free", "static_optimisation")].activation[:, 1].max() < 1e-9
    for c in ("free", "load_1kg", "tensed"):
        so = np.sum(results[(c, "static_optimisation")].activation ** 2)
        rule = np.sum(results[(c, "seed_rule")].activation ** 2)
        assert so <= rule * (1 + 1e-9)


def _force_of(s, res):
    """F(a) (T, m) N at the result's final fibre state (what its activations were solved on)."""
    mc = MuscleConstants.from_arm(s.arm)
    state = fibre_state(res.musculotendon_length, res.force, mc)
    return lambda a: tendon_force_at(a, state, res.fibre_velocity, mc, s.model)


def _slsqp(r, tau, force_of, lower, start):
    """One sample by a general constrained optimiser: min sum a^2, R^T F(a) = tau, a in box."""

    def torque(a):
        return r.T @ force_of(a[None])[0]

    out = minimize(
        lambda a: a @ a,
        start,
        jac=lambda a: 2 * a,
        method="SLSQP",
        bounds=[(lo, 1.0) for lo in lower],
        constraints={"type": "eq", "fun": lambda a: torque(a) - tau},
        options={"ftol": 1e-14, "maxiter": 500},
    )
    assert out.success, out.message
    return out.x


@pytest.mark.parametrize("condition", ["free", "load_1kg", "tensed"])
def test_static_optimisation_matches_a_general_optimiser(results, condition):
    s = study(condition)
    res = results[(condition, "static_optimisation")]
    force_of = _force_of(s, res)
    lower = np.full(4, s.model.co_contraction)
    for t in (5, 39, 62, 75, 95):
        one = lambda a, t=t: force_of(np.broadcast_to(a, res.force.shape))[t : t + 1]  # noqa: E731
        ref = _slsqp(res.moment_arm[t], res.torque[t], one, lower, np.full(4, 0.5))
        np.testing.assert_allclose(res.activation[t], ref, atol=2e-6)


# --- an independent derivation of the arm's torques, forces, activations and missing torque ---
# Closed-form Lagrangian dynamics of the planar two-link arm, muscle geometry from the
# attachment points, and per sample, per joint the exact minimiser of a_f^2 + a_e^2 (one muscle
# of the pair above its floor) with every tendon force found by a scalar root-finder; only the
# normalised constitutive curves (checked against the seed's values above) are shared with the
# code under test.


def _seed_motion(motion, t):
    """The seed's rest-to-rest motion (SPEC section 4) written out: q, qd, qdd (T, n)."""
    th0, d = np.radians(motion.start_deg), np.radians(motion.range_deg)
    w = np.pi / motion.duration
    c1, c3 = np.cos(w * t)[:, None], np.cos(3 * w * t)[:, None]
    s1, s3 = np.sin(w * t)[:, None], np.sin(3 * w * t)[:, None]
    q = 9 * d / 16 * (-c1 + c3 / 9) + th0 + d / 2
    return q, 9 * w * d / 16 * (s1 - s3 / 3), 9 * w**2 * d / 16 * (c1 - c3)


def _two_link_torque(arm, q, qd, qdd, g=9.81):
    """Joint torques (T, 2) N m of two solid cylinders with a point load at the hand, by
    Lagrange's equations (gravity -y, angles about +z from +x)."""
    (l1, l2), (m1, m2) = (lk.length for lk in arm.links), (lk.mass for lk in arm.links)
    i1, i2 = (lk.mass * (3 * lk.radius**2 + lk.length**2) / 12 for lk in arm.links)
    mf = m2 + arm.load_mass  # forearm and load as one body: mass, COM distance, inertia
    cf = (m2 * l2 / 2 + arm.load_mass * l2) / mf
    i_f = i2 + m2 * (l2 / 2 - cf) ** 2 + arm.load_mass * (l2 - cf) ** 2
    (a, b), (da, db), (dda, ddb) = q.T, qd.T, qdd.T
    h11 = i1 + m1 * (l1 / 2) ** 2 + i_f + mf * (l1**2 + cf**2 + 2 * l1 * cf * np.cos(b))
    h12 = i_f + mf * (cf**2 + l1 * cf * np.cos(b))
    h22 = i_f + mf * cf**2
    h = mf * l1 * cf * np.sin(b)
    g1 = g * ((m1 * l1 / 2 + mf * l1) * np.cos(a) + mf * cf * np.cos(a + b))
    g2 = g * mf * cf * np.cos(a + b)
    return np.stack(
        [
            h11 * dda + h12 * ddb - h * (2 * da * db + db**2) + g1,
            h12 * dda + h22 * ddb + h * da**2 + g2,
        ],
        axis=1,
    )


def _path(arm, muscle, q):
    """Musculotendon length (T,) m and moment arm -dl/dq (T,) m of a one-joint muscle."""
    j = arm.body_index(muscle.origin_body)
    assert arm.body_index(muscle.insertion_body) == j + 1  # origin proximal, one joint
    joint = np.array([arm.links[j - 1].length if j else 0.0, 0.0])  # in the proximal frame
    c, s = np.cos(q[:, j]), np.sin(q[:, j])
    lever = np.stack([c, s], 1) * muscle.insertion[0] + np.stack([-s, c], 1) * muscle.insertion[1]
    span = np.asarray(muscle.origin) - joint - lever
    length = np.linalg.norm(span, axis=1)
    return length, np.sum(span * np.stack([-lever[:, 1], lever[:, 0]], 1), axis=1) / length


class _Unit:
    """One musculotendon unit: the tendon force at an activation, and the activation for a
    force, each by a scalar root-finder on  F = F0 F^M(a, l^M(F), v) cos(alpha(F))."""

    def __init__(self, muscle, model):
        self.l0, self.slack, self.f0 = (
            muscle.optimal_fibre_length,
            muscle.tendon_slack_length,
            muscle.max_isometric_force,
        )
        self.width = self.l0 * np.sin(np.radians(muscle.pennation_deg))
        self.vmax = model.max_shortening_velocity * self.l0
        self.rest = model.rest_vmax_fraction

    def fibre(self, lmt, force):
        f = force / self.f0  # tendon eq 9 inverted by hand: toe up to 0.5 F0, then linear
        eps = f / 25 if f < 0.5 else (f + 0.25) / 37.5
        along = max(lmt - (1 + eps) * self.slack, 0.0)
        lm = np.hypot(along, self.width)
        return lm, along / lm

    def along_tendon(self, a, lmt, force, v):
        lm, cos = self.fibre(lmt, force)
        n, u = lm / self.l0, v / (self.vmax * (self.rest + (1 - self.rest) * a))
        active = curves.active_force_length(n) * curves.force_velocity(u)
        return self.f0 * (curves.passive_force_length(n) + a * active) * cos

    def force(self, a, lmt, v):
        def gap(f):
            return self.along_tendon(a, lmt, f, v) - f

        return brentq(gap, 0.0, 4 * self.f0, xtol=1e-12) if gap(0.0) > 0 else 0.0

    def activation(self, force, lmt, v, lo):
        def gap(a):
            return self.along_tendon(a, lmt, force, v) - force

        return lo if gap(lo) >= 0 else 1.0 if gap(1.0) <= 0 else brentq(gap, lo, 1, xtol=1e-13)


def _independent_solution(s):
    """Torque (T, 2), tendon forces and activations (T, 4), missing torque (T, 2) of a
    condition whose muscles are [flexor J0, extensor J0, flexor J1, extensor J1]."""
    arm, lo = s.arm, s.model.co_contraction
    t = np.linspace(0, s.motion.duration, round(s.motion.duration * s.motion.sample_rate) + 1)
    tau = _two_link_torque(arm, *_seed_motion(s.motion, t))
    paths = np.array([_path(arm, m, _seed_motion(s.motion, t)[0]) for m in arm.muscles])
    lmt, r = paths[:, 0].T, paths[:, 1].T  # (T, 4) m
    assert np.all(r[:, [0, 2]] > 0) and np.all(r[:, [1, 3]] < 0)
    units = [_Unit(m, s.model) for m in arm.muscles]
    v = np.zeros_like(lmt)  # fibre velocities: fixed point with the fibre lengths they give
    for _ in range(60):
        force, act, missing = np.zeros_like(lmt), np.full_like(lmt, lo), np.zeros_like(tau)
        for i in range(len(t)):
            for j, (fl, ex) in enumerate(((0, 1), (2, 3))):
                fmin = [units[k].force(lo, lmt[i, k], v[i, k]) for k in (fl, ex)]
                fmax = [units[k].force(1.0, lmt[i, k], v[i, k]) for k in (fl, ex)]
                rest = r[i, fl] * fmin[0] + r[i, ex] * fmin[1]
                top = r[i, fl] * fmax[0] + r[i, ex] * fmin[1]
                bottom = r[i, fl] * fmin[0] + r[i, ex] * fmax[1]
                need = tau[i, j]
                if need >= rest:  # flexion: the extensor rests on its floor
                    f = min(need, top) - r[i, ex] * fmin[1]
                    force[i, [fl, ex]] = f / r[i, fl], fmin[1]
                    missing[i, j] = max(need - top, 0.0)
                else:
                    f = max(need, bottom) - r[i, fl] * fmin[0]
                    force[i, [fl, ex]] = fmin[0], f / r[i, ex]
                    missing[i, j] = min(need - bottom, 0.0)
        lm = np.array(
            [
                [u.fibre(lmt[i, k], force[i, k])[0] for k, u in enumerate(units)]
                for i in range(len(t))
            ]
        )
        v, v_old = np.gradient(lm, t[1] - t[0], axis=0, edge_order=2), v  # seed eq 18
        if np.abs(v - v_old).max() < 1e-12:
            break
    for i in range(len(t)):
        for k, u in enumerate(units):
            act[i, k] = u.activation(force[i, k], lmt[i, k], v[i, k], lo)
    return tau, force, act, missing


@pytest.mark.parametrize("condition", ["free", "load_1kg", "tensed"])
def test_arm_matches_an_independent_derivation(results, condition):
    """Torques, tendon forces and activations (static optimisation, co-contraction floor
    included) against the derivation above, at every sample."""
    s = study(condition)
    res = results[(condition, "static_optimisation")]
    tau, force, act, missing = _independent_solution(s)
    np.testing.assert_allclose(res.torque, tau, rtol=0, atol=1e-9)  # N m
    np.testing.assert_allclose(res.force, force, rtol=0, atol=1e-6)  # N
    np.testing.assert_allclose(res.activation, act, rtol=0, atol=1e-6)
    assert np.abs(missing).max() == 0.0  # the shipped conditions are producible
    # at rest (both ends) the torques are the moments of the weights about each joint
    (l1, l2), (m1, m2) = (lk.length for lk in s.arm.links), (lk.mass for lk in s.arm.links)
    for i in (0, -1):
        q0, q01 = res.q[i, 0], res.q[i, :].sum()
        x_elbow, x_forearm, x_hand = l1 * np.cos(q0), l2 / 2 * np.cos(q01), l2 * np.cos(q01)
        elbow = 9.81 * (m2 * x_forearm + s.arm.load_mass * x_hand)
        shoulder = 9.81 * (m1 * x_elbow / 2 + (m2 + s.arm.load_mass) * x_elbow) + elbow
        np.testing.assert_allclose(tau[i], [shoulder, elbow], rtol=1e-12)


def test_infeasible_load_is_reported_without_co_contraction():
    s = study("load_1kg")
    heavy = s.model_copy(update={"arm": s.arm.model_copy(update={"load_mass": 5.0})})
    res = solve_arm(heavy)
    gaps = torque_shortfalls(res, ["shoulder", "elbow"])
    # the missing torque, sample by sample, is what the independent derivation finds
    _, _, _, missing = _independent_solution(heavy)
    np.testing.assert_allclose(res.torque_residual, missing, rtol=0, atol=1e-6)  # N m
    expected = []
    for j, joint in enumerate(["shoulder", "elbow"]):
        bad = np.abs(missing[:, j]) > 1e-6
        edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            expected.append((joint, res.time[a], res.time[b - 1], missing[a:b, j]))
    assert [(g.joint, g.start_s, g.end_s) for g in gaps] == [e[:3] for e in expected]
    for g, (*_, span) in zip(gaps, expected, strict=True):
        assert g.peak_Nm == pytest.approx(span[np.argmax(np.abs(span))], abs=1e-6)
    # both joints lack flexion while the loaded arm is swung up (J0 from rest on)
    assert gaps[0].joint == "shoulder" and gaps[0].start_s == 0.0 and gaps[0].peak_Nm > 0
    assert any(g.joint == "elbow" and g.peak_Nm > 1.0 for g in gaps)
    short = res.torque_residual[:, 1] > 1e-6  # elbow short of flexion
    assert res.activation[short, 2].min() == pytest.approx(1.0, abs=1e-12)  # flexor saturated
    assert res.activation[short, 3].max() == 0.0  # ... and the extensor at rest
    # the residual is the least the muscles can miss: a general optimiser cannot do better
    force_of = _force_of(heavy, res)
    for t in np.flatnonzero(short)[::15]:
        one = lambda a, t=t: force_of(np.broadcast_to(a, res.force.shape))[t : t + 1]  # noqa: E731

        def miss(a, t=t, one=one):
            return np.sum((res.torque[t] - res.moment_arm[t].T @ one(a[None])[0]) ** 2)

        ref = minimize(miss, np.full(4, 0.5), bounds=[(0, 1)] * 4, method="trust-constr")
        assert miss(res.activation[t]) <= ref.fun + 1e-6


def test_box_qp_out_of_reach_takes_the_smallest_closest_point():
    """Row 1 cannot reach 5 (x0 <= 1); row 2 is met by any x1 = x2: take x1 = x2 = 0."""
    a = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, -1.0]]])
    x, resid = box_qp(a, np.array([[5.0, 0.0]]), np.zeros((1, 3)), np.ones((1, 3)))
    np.testing.assert_allclose(x, [[1.0, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(resid, [[-4.0, 0.0]], atol=1e-12)


def test_static_optimisation_is_exact_for_a_nonlinear_force():
    """F(a) = 10 a^2 per muscle, two antagonists on one joint: the optimum is analytic."""
    r = np.array([[[0.05], [-0.02]]])  # (T, m, n) m

    def force_of(a):
        return 10.0 * a**2

    a, produced = static_optimisation(r, np.array([[0.2]]), force_of, np.full((1, 2), 0.1))
    # extensor at its floor 0.1 pulls 0.02 * 0.1 N m: the flexor covers the rest
    flexor = np.sqrt((0.2 + 0.02 * 10 * 0.01) / (0.05 * 10))
    np.testing.assert_allclose(a, [[flexor, 0.1]], atol=1e-12)
    np.testing.assert_allclose(produced, [[0.2]], atol=1e-12)


def test_static_optimisation_beats_an_alternative_split():
    """Duplicate every muscle: SO shares each load equally between the twins, which halves
    the activations and so beats using one twin only."""
    s = study("free")
    extra = [m.model_copy(update={"name": m.name + "_2"}) for m in s.arm.muscles]
    arm = s.arm.model_copy(update={"muscles": list(s.arm.muscles) + extra})
    res = solve_arm(s.model_copy(update={"arm": arm}))
    single = solve_arm(s).activation
    np.testing.assert_allclose(res.activation[:, :4], res.activation[:, 4:], atol=1e-6)
    assert np.sum(res.activation**2) < 0.75 * np.sum(single**2)
    assert np.abs(res.torque_residual).max() < 1e-6


def test_spindle_volume_constant_over_motion(results):
    s = study("load_1kg")
    res = results[("load_1kg", "static_optimisation")]
    mc = MuscleConstants.from_arm(s.arm)
    volume = spindle_volume(mc.max_isometric_force, mc.optimal_fibre_length, 343232.75)
    long, short = spindle_semi_axes(res.fibre_length, volume)
    # PCSA = F0 / 3.5 kgf/cm^2: 24 kgf -> 6.857 cm^2
    assert volume[0] == pytest.approx(2 / 3 * 24 / 3.5 * 1e-4 * 0.2, rel=1e-12)
    for k in range(4):
        vols = []
        for t in range(0, len(res.time), 10):
            centre = np.append(0.5 * (res.origin[t, k] + res.insertion[t, k]), 0.0)
            axis = np.append(res.origin[t, k] - res.insertion[t, k], 0.0)
            v, f = spindle_mesh(centre, axis, long[t, k], short[t, k], 24, 25)
            vols.append(mesh_volume(v, f))
        vols = np.array(vols)
        assert np.ptp(vols) / vols.mean() < 1e-3
        assert vols.mean() == pytest.approx(volume[k], rel=0.02)  # tessellation error only
        # thicker as the fibre shortens
        i_short, i_long = np.argmin(res.fibre_length[:, k]), np.argmax(res.fibre_length[:, k])
        assert short[i_short, k] > short[i_long, k]


def test_activation_colour():
    np.testing.assert_allclose(
        activation_colour([0.0, 0.25, 1.0]), [[1, 1, 1], [1, 0.75, 0.75], [1, 0, 0]]
    )


def test_configs_validate_and_match_defaults():
    cfg, _ = load_config(ARM.config_model(), [ARM.default_config])
    base = cfg.muscles.base
    assert base == ArmStudyParams()
    assert set(cfg.muscles.conditions) == {"free", "load_1kg", "tensed"}
    total_kgf = sum(m.max_isometric_force for m in base.arm.muscles) / 9.80665
    assert total_kgf == pytest.approx(40.0)
    assert study("load_1kg").arm.load_mass == 1.0
    assert study("tensed").model.co_contraction > 0


def test_bad_inputs_raise_clear_errors():
    with pytest.raises(ValueError, match="is not a body"):
        ArmParams(muscles=[{"name": "x", "origin_body": "pelvis"}])
    with pytest.raises(ValueError, match="motion.start_deg"):
        ArmStudyParams(motion={"start_deg": [0.0]})
    with pytest.raises(ValueError, match="extra"):
        ModelParams(unknown=1)
