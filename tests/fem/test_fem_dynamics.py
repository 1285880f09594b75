"""Dynamics verification: energy conservation, damped decay rate, second-order convergence."""

import numpy as np
import pytest
import scipy.linalg as sla
from fem_meshes import box_mesh

import physanim.fem.newmark as newmark_module
from physanim.fem.geometry import node_dofs
from physanim.fem.linsolve import has_cholmod
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.newmark import Newmark, State
from physanim.fem.params import SimulateParams
from physanim.fem.pardiso import has_pardiso
from physanim.fem.statics import solve_static


def _cantilever(eta, mass="consistent", formulation="anp"):
    nodes, tets = box_mesh((2, 2, 4), (0.01, 0.01, 0.02))
    params = SimulateParams(mass=mass, formulation=formulation)
    model = build_model(nodes, tets, TetMaterials.uniform(len(tets), eta=eta), params)
    fixed = node_dofs(np.flatnonzero(nodes[:, 2] == 0))
    f = np.zeros(model.n_dofs)
    f[3 * np.flatnonzero(np.isclose(nodes[:, 2], 0.02))] = 1e-3
    d0 = solve_static(model.K, fixed, np.zeros(len(fixed)), f)  # released from a bent pose
    return model, fixed, d0


def _run(model, fixed, d0, dt, n_steps):
    nm = Newmark(model.K, model.M, model.C, dt, fixed)
    state = State(d0.copy(), np.zeros_like(d0), np.zeros_like(d0))
    nm.initial_acceleration(state)
    z = np.zeros(len(fixed))
    for _ in range(n_steps):
        nm.step(state, z, z, z)
    return state


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_undamped_newmark_conserves_energy(mass):
    model, fixed, d0 = _cantilever(eta=0.0, mass=mass)
    nm = Newmark(model.K, model.M, model.C, 1e-4, fixed)
    state = State(d0.copy(), np.zeros_like(d0), np.zeros_like(d0))
    nm.initial_acceleration(state)
    e0 = 0.5 * d0 @ model.K @ d0
    z = np.zeros(len(fixed))
    energies = []
    for _ in range(1000):
        nm.step(state, z, z, z)
        energies.append(0.5 * state.v @ model.M @ state.v + 0.5 * state.d @ model.K @ state.d)
    energies = np.array(energies)
    assert np.abs(energies / e0 - 1).max() < 1e-6
    assert (0.5 * state.v @ model.M @ state.v) > 0.01 * e0  # it really oscillates


def test_single_dof_damped_vibration_decays_at_analytic_rate():
    # one tet, three nodes clamped, the apex free along z only: m x'' + c x' + k x = 0
    nodes = np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.01]], float)
    tets = np.array([[0, 1, 2, 3]])
    model = build_model(nodes, tets, TetMaterials.uniform(1, E=2e5, eta=20.0, rho=1100.0))
    z = 11
    fixed = np.setdiff1d(np.arange(12), [z])
    m, c, k = (X[z, z] for X in (model.M, model.C, model.K))
    wn, zeta = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - zeta**2)
    assert 0.01 < zeta < 0.3
    x0, period = 1e-4, 2 * np.pi / wd

    def error(dt):
        nm = Newmark(model.K, model.M, model.C, dt, fixed)
        state = State(np.zeros(12), np.zeros(12), np.zeros(12))
        state.d[z] = x0
        nm.initial_acceleration(state)
        n = int(round(3 * period / dt))
        xs = np.empty(n)
        zero = np.zeros(11)
        for i in range(n):
            xs[i] = nm.step(state, zero, zero, zero).d[z]
        t = dt * np.arange(1, n + 1)
        exact = x0 * np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))
        return t, xs, np.abs(xs - exact).max()

    t, xs, e1 = error(period / 400)
    _, _, e2 = error(period / 800)
    assert e1 < 1e-3 * x0
    assert 3.6 < e1 / e2 < 4.4  # second order
    peaks = np.flatnonzero((xs[1:-1] > xs[:-2]) & (xs[1:-1] > xs[2:])) + 1
    rate = -np.polyfit(t[peaks], np.log(xs[peaks]), 1)[0]
    np.testing.assert_allclose(rate, zeta * wn, rtol=1e-3)


def test_mesh_dynamics_second_order_against_exact_solution():
    model, fixed, d0 = _cantilever(eta=2.0)
    u = np.setdiff1d(np.arange(model.n_dofs), fixed)
    K, M, C = (X[u][:, u].toarray() for X in (model.K, model.M, model.C))
    n = len(u)
    Minv = np.linalg.inv(M)
    system = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])
    t_end = 4e-3
    exact = (sla.expm(system * t_end) @ np.concatenate([d0[u], np.zeros(n)]))[:n]
    errs = [np.abs(_run(model, fixed, d0, t_end / s, s).d[u] - exact).max() for s in (40, 80)]
    assert errs[0] < 0.05 * np.abs(d0).max()
    assert 3.5 < errs[0] / errs[1] < 4.5


@pytest.mark.parametrize("slow_blas", [False, True])
@pytest.mark.parametrize("solver", ["auto", "pardiso", "cholmod", "superlu", "superlu_colamd"])
def test_split_anp_solver_matches_direct_solve(solver, slow_blas, monkeypatch):
    # PARDISO, and CHOLMOD under the reference BLAS, factorise the sparser augmented matrix
    if solver == "pardiso" and not has_pardiso() or solver == "cholmod" and not has_cholmod():
        pytest.skip(f"{solver} not installed")
    monkeypatch.setattr(newmark_module, "optimized_blas", lambda: not slow_blas)
    model, fixed, d0 = _cantilever(eta=2.0)
    direct = Newmark(model.K, model.M, model.C, 1e-4, fixed, "superlu")
    split = Newmark(model.K, model.M, model.C, 1e-4, fixed, solver, model.split)
    b = np.random.default_rng(3).normal(size=len(direct.free))
    x_ref = direct.solve(b)
    np.testing.assert_allclose(split.solve(b), x_ref, rtol=0, atol=1e-10 * np.abs(x_ref).max())
    other = split.with_dt(3e-4)  # a cached step size: same symbolic analysis, new factor
    ref = Newmark(model.K, model.M, model.C, 3e-4, fixed, "superlu").solve(b)
    np.testing.assert_allclose(other.solve(b), ref, rtol=0, atol=1e-10 * np.abs(ref).max())


@pytest.mark.parametrize("slow_blas", [False, True])
def test_solvers_split_the_anp_matrix_where_it_pays(slow_blas, monkeypatch):
    # 'auto' is PARDISO when MKL loads (always the augmented matrix), else CHOLMOD, which
    # takes the augmented matrix only under the reference BLAS
    if not has_cholmod():
        pytest.skip("CHOLMOD (scikit-sparse) not installed: the solvers' choice not run")
    monkeypatch.setattr(newmark_module, "optimized_blas", lambda: not slow_blas)
    model, fixed, _ = _cantilever(eta=2.0)
    auto = Newmark(model.K, model.M, model.C, 1e-4, fixed, "auto", model.split)
    assert auto.solver == ("pardiso" if has_pardiso() else "cholmod")
    cholmod = Newmark(model.K, model.M, model.C, 1e-4, fixed, "cholmod", model.split)
    assert (cholmod._split is not None) == slow_blas
    if has_pardiso():
        assert auto._split is not None


def test_free_blocks_and_side_by_side_match_scipys_slicing():
    """The integrator's matrices: the free-DOF blocks of matrices on one pattern cut once
    (and of matrices on different patterns, merged), and [A | B | C] built row by row, equal
    scipy's own slicing and hstack (the blocks as CSC from CSR arrays: the transpose, equal
    for these symmetric matrices up to round-off)."""
    import scipy.sparse as sp

    model, fixed, _ = _cantilever(eta=1.0)
    free = np.setdiff1d(np.arange(model.n_dofs), fixed)
    lumped = sp.diags(np.asarray(model.M.sum(axis=1)).ravel(), format="csr")  # its own pattern
    for mats in ((model.K_el, model.M, model.C), (model.K_el, lumped, model.C)):
        pattern, values = newmark_module._free_blocks(free, *mats)
        for X, v in zip(mats, values, strict=True):
            got = sp.csc_matrix((v, pattern.indices, pattern.indptr), shape=pattern.shape)
            np.testing.assert_array_equal(got.toarray(), X[free][:, free].T.toarray())
    rows = [model.M[free], model.C[free], model.K[free][:, fixed]]
    got = newmark_module._side_by_side(*rows)
    np.testing.assert_array_equal(got.toarray(), sp.hstack(rows).toarray())
