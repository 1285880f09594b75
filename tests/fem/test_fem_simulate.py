"""simulate(): driven/fixed boundary handling, quasi-static limit, corotation, guards."""

import numpy as np
import pytest
from fem_meshes import box_mesh

from physanim.fem.geometry import node_dofs
from physanim.fem.interp import catmull_rom, catmull_rom_position
from physanim.fem.materials import TetMaterials
from physanim.fem.params import SimulateParams
from physanim.fem.simulate import simulate
from physanim.fem.statics import solve_static


def _slab():
    nodes, tets = box_mesh((4, 4, 2), (0.04, 0.04, 0.01))
    fixed = np.flatnonzero(nodes[:, 2] == 0)
    top = np.flatnonzero(np.isclose(nodes[:, 2], 0.01))
    driven = top[np.linalg.norm(nodes[top, :2] - 0.02, axis=1) < 0.011]
    return nodes, tets, fixed, driven


def test_catmull_rom_interpolates_and_differentiates():
    h = 0.1
    t = h * np.arange(6)
    values = np.stack([3 * t - 1, t**2], axis=1)
    s = np.linspace(h, 4 * h, 37)[:-1]  # interior intervals: quadratics are reproduced
    pos, vel, acc = catmull_rom(values, h, s)
    np.testing.assert_allclose(pos, np.stack([3 * s - 1, s**2], axis=1), atol=1e-12)
    np.testing.assert_allclose(vel, np.stack([np.full_like(s, 3), 2 * s], axis=1), atol=1e-10)
    np.testing.assert_allclose(acc[:, 1], 2, atol=1e-8)
    np.testing.assert_allclose(catmull_rom(values, h, t)[0], values, atol=1e-12)
    wiggly = np.random.default_rng(0).normal(size=(6, 3))  # the position alone is the same
    np.testing.assert_allclose(
        catmull_rom_position(wiggly, h, s), catmull_rom(wiggly, h, s)[0], rtol=1e-14, atol=1e-15
    )


def test_drive_defect_is_the_trapezoidal_rules_error_on_the_path():
    # trapezoidal steps follow a quadratic path exactly (Catmull-Rom reproduces it): no
    # defect; on the cubic segment from (0, slope 0) to (0, slope m) the third derivative is
    # 6 m / H^3, so n steps of h = H / n leave n h^3 / 12 * 6 m / H^3 = m / (2 n^2)
    from physanim.fem.boundary import BoundaryConditions

    H = 0.1
    t = H * np.arange(6)
    traj = np.zeros((6, 1, 3))
    traj[:, 0, 0], traj[:, 0, 1] = 3 * t**2 - t + 2, -(t**2)
    bc = BoundaryConditions.checked(2, np.array([0]), traj, H, np.array([1]))
    for n in (1, 3):
        defect = bc.drive_defect(2 * H, H / n, n)
        assert defect.shape == (6,) and np.abs(defect).max() < 1e-12
    step = np.zeros((4, 1, 3))
    step[2:, 0, 2] = 1.0  # frame 1's slope: (1 - 0) / (2 H), so m = 0.5 on the unit segment
    bc = BoundaryConditions.checked(1, np.array([0]), step, H)
    for n in (1, 2, 4):
        # the end point's acceleration is the next segment's (the value the step sees there)
        times = H * np.array([1.0 - 1e-12, 1.0])
        jump = np.diff(catmull_rom(step[:, 0], H, times)[2][:, 2])[0]
        h = H / n
        expected = -0.5 / (2 * n**2) - 0.25 * h * h * jump
        assert bc.drive_defect(0.0, h, n)[2] == pytest.approx(expected, rel=1e-9)


def test_driven_nodes_follow_and_fixed_nodes_stay():
    nodes, tets, fixed, driven = _slab()
    n_frames = 16
    traj = np.zeros((n_frames, len(driven), 3))
    traj[:, :, 2] = 2e-3 * np.sin(np.linspace(0, np.pi, n_frames))[:, None]
    fixed_steps = SimulateParams(stepping="fixed")
    mat = TetMaterials.uniform(len(tets))
    res = simulate(nodes, tets, mat, driven, traj, 1 / 30, fixed, fixed_steps)
    assert res.displacements.shape == (n_frames, len(nodes), 3)
    assert res.displacements.dtype == np.float32
    np.testing.assert_allclose(res.displacements[:, driven], traj, atol=1e-9)
    assert np.abs(res.displacements[:, fixed]).max() == 0
    assert res.n_substeps == 34 and res.dt == pytest.approx(1 / 30 / 34)
    assert (np.diff(res.dissipated) >= 0).all() and res.dissipated[-1] > 0
    assert res.strain.max() > 0 and res.max_von_mises.max() > 0
    assert res.inverted_count.max() == 0
    assert (res.frame_substeps[1:] == 34).all() and res.check_steps == 0


@pytest.mark.parametrize(
    ("estimate", "precision"),
    [
        ("acceleration", "float32"),
        ("acceleration", "float64"),
        ("doubling", "float64"),
        ("acceleration", "mixed"),
    ],
)
def test_adaptive_steps_match_the_fine_fixed_reference(estimate, precision):
    # a fast jerk (1 mm in two frames) then a hold: the control refines the jerk only. The
    # jerk happens inside frames whose end points barely show it (frame 1 starts and ends at
    # rest): the estimate must see the drive's path between them, not only the free DOFs'
    # accelerations at the ends (those alone read 0.003 um here, the true error 8 um).
    nodes, tets, fixed, driven = _slab()
    mat = TetMaterials.uniform(len(tets))
    n_frames = 12
    pulse = np.r_[0, 0, 0.5, 1, 1, 1, 1, 1, 1, 1, 1, 1]
    traj = np.zeros((n_frames, len(driven), 3))
    traj[:, :, 2] = 1e-3 * pulse[:, None]
    ref = simulate(
        nodes, tets, mat, driven, traj, 1 / 30, fixed, SimulateParams(dt=2.5e-4, stepping="fixed")
    )
    tol_mm = 1e-3
    params = SimulateParams(
        dt=2.5e-4, error_tol_mm=tol_mm, precision=precision, error_estimate=estimate
    )
    res = simulate(nodes, tets, mat, driven, traj, 1 / 30, fixed, params)
    err = np.abs(res.displacements - ref.displacements).max()
    assert err < 0.01 * np.abs(ref.displacements).max()  # within 1 % of the peak
    assert err < tol_mm * 1e-3
    steps = res.frame_substeps[1:]
    assert steps.sum() < 0.5 * ref.frame_substeps.sum()  # far fewer steps
    assert steps[1:4].min() >= 4 > steps[-3:].max()  # finer through the jerk than in the hold
    assert res.frames_over_tolerance == 0
    if estimate == "doubling":  # pairs of 1, 2, 4, ... and the max; the coarse one discarded
        assert set(steps) <= {2, 4, 8, 16, 32, 64, 128, 134} and res.check_steps >= steps.sum() / 2
    else:  # no extra solves but the frames redone
        assert set(steps) <= {1, 2, 4, 8, 16, 32, 64, 128, 134} and res.check_steps < steps.sum()
    np.testing.assert_allclose(res.dissipated[-1], ref.dissipated[-1], rtol=0.02)


def test_waiting_estimates_rewind_to_the_first_frame_over_the_tolerance(monkeypatch):
    # a slow ramp lets estimates at the coarsest step size wait in batches (1, 2, 4, 8, 8:
    # frames 16-23 wait together); a jump at frame 21, felt from frame 20 on through the
    # drive's spline, fails frame 20's estimate inside that batch: the run rewinds there and
    # refines it, and ends where the run that solves every estimate at once ends (the batched
    # solve's round-off aside), frame for frame in the same substeps
    import physanim.fem.stepping as stepping

    nodes, tets, fixed, driven = _slab()
    mat = TetMaterials.uniform(len(tets))
    n_frames = 32
    path = 1e-4 * np.arange(n_frames) / n_frames
    path[21:] += 1e-3
    traj = np.zeros((n_frames, len(driven), 3))
    traj[:, :, 2] = path[:, None]
    params = SimulateParams(dt=2.5e-4, error_tol_mm=1e-3, precision="float64")
    waited = simulate(nodes, tets, mat, driven, traj, 1 / 30, fixed, params)
    monkeypatch.setattr(stepping, "ERROR_BATCH", 1)
    each = simulate(nodes, tets, mat, driven, traj, 1 / 30, fixed, params)
    np.testing.assert_array_equal(waited.frame_substeps, each.frame_substeps)
    steps = waited.frame_substeps
    assert steps[1:19].max() == 1 and steps[20:22].min() >= 4  # refined at the jerk only
    peak = np.abs(each.displacements).max()
    np.testing.assert_allclose(waited.displacements, each.displacements, rtol=0, atol=1e-9 * peak)
    np.testing.assert_allclose(waited.dissipated, each.dissipated, rtol=1e-9, atol=0)
    np.testing.assert_allclose(waited.strain, each.strain, rtol=1e-9, atol=1e-20)
    # the frames stepped after frame 21 in its batch were discarded
    assert waited.check_steps > each.check_steps and type(waited.check_steps) is int


def test_stiff_modes_ringing_does_not_pass_a_frame_of_even_substeps():
    # A ramp that starts moving at t = 0 then holds: the tissue's stiff, overdamped modes ring
    # at the step's Nyquist rate (Newmark's amplification tends to -1 for omega h >> 1). A raw
    # acceleration change over the frame cancels that ringing in frames of 2 substeps and
    # accepted them: the result ended 2.8 times over the tolerance (0.28 um). The
    # substep-centred change does not, and the start is refined until the tolerance holds.
    nodes, tets, fixed, driven = _slab()
    mat = TetMaterials.uniform(len(tets))
    n_frames = 30
    traj = np.zeros((n_frames, len(driven), 3))
    traj[:, :, 0] = 1e-3 * np.clip(np.arange(n_frames) / 9, 0, 1)[:, None]
    ref = simulate(
        nodes, tets, mat, driven, traj, 1 / 30, fixed, SimulateParams(dt=2.5e-4, stepping="fixed")
    )
    tol_mm = 1e-4
    res = simulate(
        nodes,
        tets,
        mat,
        driven,
        traj,
        1 / 30,
        fixed,
        SimulateParams(dt=2.5e-4, error_tol_mm=tol_mm),
    )
    err = np.abs(res.displacements - ref.displacements).max()
    assert err < tol_mm * 1e-3 and res.frames_over_tolerance == 0
    steps = res.frame_substeps[1:]
    assert steps[0] >= 64 and steps[-5:].max() <= 2  # the start resolved, the hold coarse
    assert steps.sum() < 0.5 * ref.frame_substeps.sum()


def test_slow_driving_reaches_static_equilibrium():
    nodes, tets, fixed, driven = _slab()
    mat = TetMaterials.uniform(len(tets))
    n_frames = 31
    ramp = np.clip(np.linspace(0, 1.5, n_frames), 0, 1)  # ramp over 1 s, then hold 0.5 s
    traj = np.zeros((n_frames, len(driven), 3))
    traj[:, :, 0] = 1e-3 * ramp[:, None]
    traj[:, :, 2] = -1e-3 * ramp[:, None]
    res = simulate(nodes, tets, mat, driven, traj, 0.05, fixed, SimulateParams(dt=2e-3))
    pres = node_dofs(np.concatenate([driven, fixed]))
    vals = np.concatenate([traj[-1], np.zeros((len(fixed), 3))]).ravel()
    from physanim.fem.model import build_model

    static = solve_static(build_model(nodes, tets, mat).K, pres, vals).reshape(-1, 3)
    err = np.abs(res.displacements[-1] - static).max()
    assert err < 0.01 * np.abs(static).max()
    # it lags the static answer during the ramp (inertia + viscosity), not ahead of it
    assert res.kinetic[10] > 0


def test_corotational_matches_linear_for_small_motion_and_removes_rotation_artefacts():
    nodes, tets, fixed, driven = _slab()
    mat = TetMaterials.uniform(len(tets))
    traj = np.zeros((6, len(driven), 3))
    traj[:, :, 2] = 1e-5 * np.linspace(0, 1, 6)[:, None]
    # the linear run on the reference path: corotational runs always take fixed steps
    fixed_steps = SimulateParams(dt=5e-3, stepping="fixed")
    lin = simulate(nodes, tets, mat, driven, traj, 0.02, fixed, fixed_steps)
    cor = simulate(
        nodes, tets, mat, driven, traj, 0.02, fixed, SimulateParams(dt=5e-3, corotational=True)
    )
    rel = np.abs(cor.displacements - lin.displacements).max() / np.abs(lin.displacements).max()
    assert rel < 1e-3
    # a rigid 60 degree rotation prescribed on all nodes but one: no strain energy when corotated
    angle = np.linspace(0, np.pi / 3, 6)
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    drive_all = np.arange(1, len(nodes))
    x, y = nodes[drive_all, 0], nodes[drive_all, 1]
    rigid = np.zeros((6, len(drive_all), 3))
    rigid[:, :, 0] = c * x - s * y - x
    rigid[:, :, 1] = s * x + c * y - y
    out = {}
    for corot in (False, True):
        out[corot] = simulate(
            nodes,
            tets,
            mat,
            drive_all,
            rigid,
            0.02,
            None,
            SimulateParams(dt=5e-3, corotational=corot, stepping="fixed"),
        )
    assert out[False].strain[-1] > 1e3 * max(out[True].strain[-1], 1e-12)
    assert out[True].max_von_mises[-1] < 1e-2 * out[False].max_von_mises[-1]


def test_inverted_elements_are_reported():
    nodes, tets, fixed, driven = _slab()
    traj = np.zeros((3, len(driven), 3))
    traj[1:, :, 2] = [[-0.004], [-0.012]]  # pushes top nodes through the 1 cm slab
    res = simulate(nodes, tets, TetMaterials.uniform(len(tets)), driven, traj, 0.02, fixed)
    assert res.inverted_count[0] == 0 and res.inverted_count[-1] > 0
    assert res.inverted_tets.size >= res.inverted_count[-1]


def test_bad_inputs_are_rejected():
    nodes, tets, fixed, driven = _slab()
    mat = TetMaterials.uniform(len(tets))
    with pytest.raises(ValueError, match="driven_traj"):
        simulate(nodes, tets, mat, driven, np.zeros((5, 2, 3)), 0.02, fixed)
    with pytest.raises(ValueError, match="share nodes"):
        simulate(nodes, tets, mat, driven, np.zeros((5, len(driven), 3)), 0.02, driven[:2])
    with pytest.raises(ValueError, match="nu"):
        simulate(
            nodes,
            tets,
            TetMaterials.uniform(len(tets), nu=0.5),
            driven,
            np.zeros((5, len(driven), 3)),
            0.02,
            fixed,
        )
    with pytest.raises(ValueError, match="inverted"):
        simulate(nodes, tets[:, [1, 0, 2, 3]], mat, driven, np.zeros((5, len(driven), 3)), 0.02)
