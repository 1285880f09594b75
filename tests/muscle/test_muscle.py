"""Muscle-driven arm (issue 9): curves, geometry, force sharing, activations, shapes, configs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

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
    # tensed: the floor changes the solution (seed's linearised floor: extensor 0.134)
    if condition == "tensed":
        assert res.activation[39, 3] == pytest.approx(0.245, abs=1e-3)


def test_infeasible_load_is_reported_without_co_contraction():
    s = study("load_1kg")
    heavy = s.model_copy(update={"arm": s.arm.model_copy(update={"load_mass": 5.0})})
    res = solve_arm(heavy)
    gaps = torque_shortfalls(res, ["shoulder", "elbow"])
    elbow = [g for g in gaps if g.joint == "elbow" and g.peak_Nm > 0]
    assert elbow and max(g.peak_Nm for g in elbow) > 5.0  # N m of flexion missing
    shoulder = max(g.peak_Nm for g in gaps if g.joint == "shoulder")
    assert shoulder == pytest.approx(np.abs(res.torque_residual[:, 0]).max())
    assert shoulder == pytest.approx(15.4, abs=0.1)
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
