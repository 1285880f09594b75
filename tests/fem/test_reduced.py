"""The reduced (POD) preview against full FEM runs of the same and of edited materials."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from physanim.fem import reduced
from physanim.fem.actuation import Actuation, StressBasis
from physanim.fem.boundary import BoundaryConditions, SpringDrive
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.params import SimulateParams
from physanim.fem.problem import FemProblem
from physanim.fem.simulate import simulate, simulate_problem
from physanim.fem.statics import free_dofs
from tests.fem.fem_meshes import box_mesh


def driven_block(n_frames: int, shape=(4, 3, 3)):
    """A 4 x 3 x 3 cm block of tissue: bottom fixed, top face turned and lifted (held for
    the first 3 frames, so the run starts at rest), two side nodes pulled by springs."""
    nodes, tets = box_mesh(shape, (0.04, 0.03, 0.03))
    bottom = np.flatnonzero(nodes[:, 2] < 1e-9)
    top = np.flatnonzero(nodes[:, 2] > 0.03 - 1e-9)
    s = np.clip(np.linspace(-0.1, 1.2, n_frames), 0, None) ** 2  # smooth start from rest
    rel = nodes[top] - nodes[top].mean(axis=0)
    turn = np.stack([-rel[:, 1], rel[:, 0], np.zeros(len(top))], axis=1)
    traj = s[:, None, None] * (0.08 * turn[None] + np.array([0.0, 0.0, 1e-3]))
    side = np.flatnonzero((nodes[:, 0] < 1e-9) & (nodes[:, 2] > 0.005) & (nodes[:, 2] < 0.025))
    targets = np.zeros((n_frames, len(side), 3))
    targets[:, :, 0] = -5e-4 * np.sin(np.pi * s / s.max())[:, None]
    springs = SpringDrive(side, np.full(len(side), 500.0), targets)
    fixed = np.r_[bottom]
    return nodes, tets, top, traj, fixed, springs


def run_full(nodes, tets, mats, top, traj, fixed, springs, frame_dt, params):
    return simulate(nodes, tets, mats, top, traj, frame_dt, fixed_idx=fixed, params=params,
                    springs=springs)  # fmt: skip


def conditions(nodes, top, traj, fixed, springs, frame_dt) -> BoundaryConditions:
    return BoundaryConditions.checked(len(nodes), top, traj, frame_dt, fixed, springs)


def actuation_of(nodes, tets, n_frames: int) -> Actuation:
    """Active stress over the block: 4 patches, each coefficient a smooth pulse over the run."""
    basis = StressBasis.covering(nodes, tets, 0.02)
    pulse = np.sin(np.pi * np.linspace(0.0, 1.0, n_frames)) ** 2
    amplitude = np.random.default_rng(4).normal(size=(basis.n_patches, 5)) * 2e3  # Pa
    return Actuation(basis, pulse[:, None, None] * amplitude[None])


@pytest.mark.parametrize("actuated", [False, True])
def test_a_basis_that_spans_every_step_reproduces_the_full_run(actuated: bool) -> None:
    """One substep per frame: the frames are every Newmark step, so a basis of all the
    snapshots (fewer than the free DOFs) spans the whole trajectory and the Galerkin run
    equals the full run to round-off (displacements, energies, dissipation, stress), with the
    drive's springs and, ``actuated``, an active stress too (whose residual then vanishes).
    The full run's solves in float64: PARDISO's float32 ones round each step's right-hand
    side too (energies then 2e-6 apart), which is the solver's error, not the basis'."""
    frame_dt, n_frames = 0.004, 40
    nodes, tets, top, traj, fixed, springs = driven_block(n_frames)
    mats = TetMaterials.uniform(len(tets), 5e4, 0.45, 200.0, 1100.0)
    params = SimulateParams(stepping="fixed", dt=frame_dt, precision="float64")
    bc = conditions(nodes, top, traj, fixed, springs, frame_dt)
    actuation = actuation_of(nodes, tets, n_frames) if actuated else None
    problem = FemProblem(nodes, tets, mats, bc).with_actuation(actuation)
    full = simulate_problem(problem, params)
    free = free_dofs(3 * len(nodes), bc.prescribed_dofs)
    basis = reduced.pod_basis(full.displacements.astype(np.float64), free, 1 - 1e-15, 1000)
    assert basis.size < len(free) / 4  # the drive has few patterns (and float32 round-off)
    model = build_model(nodes, tets, mats, params)
    run = reduced.simulate_reduced(model, bc, basis, full.frame_substeps, actuation=actuation)
    res = run.result
    estimate = reduced.residual_estimate(model, bc, basis, run, actuation=actuation)
    assert np.abs(estimate).max() < 1e-5 * np.abs(full.displacements).max()
    error = reduced.displacement_error(res.displacements, full.displacements)
    print(f"modes {basis.size} of {len(free)} free DOFs: error {error}")
    assert error["peak"] < 1e-6  # float32 output: 1e-7 relative
    for name in ("strain", "kinetic", "dissipated", "max_von_mises", "p99_von_mises"):
        ref = getattr(full, name)
        np.testing.assert_allclose(getattr(res, name), ref, atol=1e-6 * np.abs(ref).max())


@pytest.fixture(scope="module", params=["kinematic", "actuated"])
def edited_block(request):
    """Full runs (adaptive stepping) of a two-region block: the basis material, and the
    right half made twice as stiff and viscous; driven kinematically (the top turned and
    lifted, springs at a side) or by an active stress alone (the bottom fixed)."""
    frame_dt, n_frames = 1 / 30, 30
    nodes, tets, top, traj, fixed, springs = driven_block(n_frames, (6, 4, 4))
    labels = (nodes[tets].mean(axis=1)[:, 0] > 0.02).astype(np.int64)
    base = TetMaterials.uniform(len(tets), 5e4, 0.45, 200.0, 1100.0)
    edited = dataclasses.replace(
        base, E=np.where(labels == 1, 2 * base.E, base.E), eta=np.where(labels, 400.0, 200.0)
    )
    params = SimulateParams(dt=1e-3)
    if request.param == "kinematic":
        bc, actuation = conditions(nodes, top, traj, fixed, springs, frame_dt), None
    else:
        none = np.zeros(0, np.int64)
        bc = BoundaryConditions.checked(len(nodes), none, np.zeros((n_frames, 0, 3)),
                                        frame_dt, fixed)  # fmt: skip
        actuation = actuation_of(nodes, tets, n_frames)
    runs = [simulate_problem(FemProblem(nodes, tets, m, bc).with_actuation(actuation), params)
            for m in (base, edited)]  # fmt: skip
    return request.param, nodes, tets, labels, (base, edited), runs, bc, actuation, params


#: bounds on the edited block's preview error (share of the peak displacement) by drive and
#: basis; measured: kinematic 5.5 % (snapshots alone, 2 modes) and 0.10 % (with the region
#: sensitivities, 11 modes); actuated 36 % and 0.35 % (4 modes; 5.6 % with the first-order
#: sensitivities alone: a force-driven response scales with the compliance)
PREVIEW_BOUNDS = {
    ("kinematic", False): 0.08, ("kinematic", True): 0.003,
    ("actuated", False): 0.5, ("actuated", True): 0.01,
}  # fmt: skip


@pytest.mark.parametrize("sensitivities", [False, True], ids=["snapshots", "sensitivities"])
def test_an_edited_material_previewed_in_the_basis_of_another(edited_block, sensitivities):
    """The edited material (right half 2x E and eta) in the basis of the uniform run, against
    its own full run, within ``PREVIEW_BOUNDS``. The residual estimate, made without the full
    run, is within a factor of 2 of the true error."""
    drive, nodes, tets, labels, (base, edited), runs, bc, actuation, params = edited_block
    full_base, full_edit = runs
    model_base = build_model(nodes, tets, base, params)
    extra = None
    if sensitivities:
        rebuild = lambda m: build_model(nodes, tets, m, params)  # noqa: E731
        extra = reduced.material_sensitivities(
            model_base, bc, full_base.displacements, full_base.times, labels, rebuild, base
        )
    free = free_dofs(3 * len(nodes), bc.prescribed_dofs)
    basis = reduced.pod_basis(full_base.displacements, free, extra=extra)
    model = build_model(nodes, tets, edited, params)
    run = reduced.simulate_reduced(model, bc, basis, full_base.frame_substeps, actuation=actuation)
    error = reduced.displacement_error(run.result.displacements, full_edit.displacements)
    est_field = reduced.residual_estimate(model, bc, basis, run, actuation=actuation)
    u = run.result.displacements
    estimate = reduced.displacement_error(u + est_field, u)
    print(f"{drive}, modes {basis.size}: error {error}, estimate {estimate}")
    assert error["peak"] < PREVIEW_BOUNDS[drive, sensitivities]
    regions = reduced.region_errors(u, full_edit.displacements, tets, labels, ["left", "right"])
    assert max(regions.values()) == pytest.approx(error["peak"])  # every node is in a region
    assert error["peak"] / 2 < estimate["peak"] < 2 * error["peak"]
    # the basis material itself, previewed in its own basis: the truncation alone
    own = reduced.simulate_reduced(
        model_base, bc, basis, full_base.frame_substeps, actuation=actuation
    )
    own_error = reduced.displacement_error(own.result.displacements, full_base.displacements)
    assert own_error["peak"] < 1e-3


def test_bad_input_is_refused_with_the_rule() -> None:
    nodes, tets, top, traj, fixed, springs = driven_block(5, (2, 2, 2))
    bc = conditions(nodes, top, traj, fixed, springs, 0.01)
    free = free_dofs(3 * len(nodes), bc.prescribed_dofs)
    with pytest.raises(ValueError, match="all zero"):
        reduced.pod_basis(np.zeros((5, len(nodes), 3)), free)
    basis = reduced.pod_basis(np.random.default_rng(0).normal(size=(5, len(nodes), 3)), free)
    model = build_model(nodes, tets, TetMaterials.uniform(len(tets)))
    with pytest.raises(ValueError, match=r"substeps must be \(T,\)"):
        reduced.simulate_reduced(model, bc, basis, np.ones(3, dtype=np.int64))
    other = reduced.PodBasis(basis.phi[:-3], basis.free[:-3], basis.singular_values)
    with pytest.raises(ValueError, match="other free DOFs"):
        reduced.simulate_reduced(model, bc, other, np.ones(5, dtype=np.int64))


def test_a_disabled_preview_leaves_the_simulate_key_alone() -> None:
    """Full runs keep their stage keys: a disabled ``reduced`` section is not dumped (the key
    is made from the dump); an enabled one is, and round-trips through the provenance."""
    from tasks.simulate import SimulateStageParams

    assert "reduced" not in SimulateStageParams().model_dump(mode="json")
    off = SimulateStageParams(reduced={"enabled": False, "max_modes": 10})
    assert off.model_dump(mode="json") == SimulateStageParams().model_dump(mode="json")
    on = SimulateStageParams(reduced={"enabled": True})
    assert on.model_dump(mode="json")["reduced"]["enabled"] is True
    assert SimulateStageParams.model_validate(on.model_dump(mode="json")) == on
    with pytest.raises(ValueError, match="set corotational: false"):
        SimulateStageParams(reduced={"enabled": True}, corotational=True)
