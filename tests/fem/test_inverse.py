"""The inverse step (physanim.fem.inverse): a known actuation recovered from the motion it
makes, no actuation where nothing moves, the least squares against a direct solve."""

import numpy as np
import pytest
from fem_meshes import box_mesh

from physanim.fem.actuation import StressBasis, model_force_operator
from physanim.fem.boundary import BoundaryConditions
from physanim.fem.inverse import LeastSquares, fit_actuation
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.statics import solve_static


def _slab(shape, size):
    """A slab held at its bottom (z = 0) whose top nodes are observed; the top's first node
    column is driven (a prescribed motion, like the turning mandible)."""
    nodes, tets = box_mesh(shape, size)
    bottom = np.flatnonzero(nodes[:, 2] == 0)
    top = np.flatnonzero(np.isclose(nodes[:, 2], size[2]))
    edge = top[nodes[top, 0] == 0]
    return nodes, tets, bottom, np.setdiff1d(top, edge), edge


def _observed_motion(model, basis, conditions, coefficients, observed):
    """The static motion (T, S, 3) m of the observed nodes under the conditions and the
    active stress of ``coefficients`` (T, P, 5) (solved frame by frame, K d = f_a)."""
    frames = conditions.prescribed(conditions.frame_dt * np.arange(len(coefficients)))[0]
    out = []
    for d_c, c in zip(frames, coefficients, strict=True):
        f = -(model_force_operator(model) @ basis.stress(c).ravel())
        d = solve_static(model.K, conditions.prescribed_dofs, d_c, f)
        out.append(d.reshape(-1, 3)[observed])
    return np.asarray(out)


def test_a_known_actuation_is_recovered_from_the_skin_motion_it_makes():
    """Random actuation of 8 patches x 5 deviatoric directions over 3 frames plus a driven
    edge: the top surface's static motion gives the coefficients back to 1 %
    with negligible regularisation."""
    nodes, tets, bottom, top, edge = _slab((4, 4, 2), (0.04, 0.04, 0.01))
    mats = TetMaterials.uniform(len(tets))
    basis = StressBasis.covering(nodes, tets, 0.018)
    assert 5 * basis.n_patches < 3 * len(top)  # more observations than unknowns
    rng = np.random.default_rng(0)
    n_frames = 3
    known = rng.normal(size=(n_frames, basis.n_patches, 5)) * 2e3  # Pa
    known[0] = 0.0  # at rest first
    edge_traj = np.zeros((n_frames, len(edge), 3))
    edge_traj[:, :, 2] = np.array([0.0, 2e-4, -1e-4])[:, None]
    conditions = BoundaryConditions.checked(len(nodes), edge, edge_traj, 10.0, bottom)
    model = build_model(nodes, tets, mats)
    targets = _observed_motion(model, basis, conditions, known, top)
    weights = np.ones((n_frames, len(top)))
    fit = fit_actuation(model, basis, conditions, top, targets, weights, 1e-14, 0.0)
    error = np.linalg.norm(fit.coefficients - known) / np.linalg.norm(known)
    print(f"recovered to {error:.2e}")
    assert error < 0.01
    np.testing.assert_allclose(fit.fitted, targets, atol=1e-3 * np.abs(targets).max())
    # the passive motion is the driven edge's alone
    assert np.abs(fit.passive[1]).max() > 1e-5 and np.abs(fit.passive[0]).max() < 1e-15


def test_the_regularisation_leaves_no_actuation_far_from_any_motion():
    """A long slab moved by actuation at one end only: the fit (default-like costs) puts
    (almost) no stress in the patches 30 mm or more from every moving skin node."""
    nodes, tets, bottom, top, _ = _slab((12, 3, 2), (0.12, 0.03, 0.01))
    mats = TetMaterials.uniform(len(tets))
    basis = StressBasis.covering(nodes, tets, 0.012)
    rng = np.random.default_rng(1)
    near = basis.centres[:, 0] < 0.02
    known = np.zeros((2, basis.n_patches, 5))
    known[1, near] = rng.normal(size=(near.sum(), 5)) * 3e3
    conditions = BoundaryConditions.checked(
        len(nodes), np.zeros(0, np.int64), np.zeros((2, 0, 3)), 10.0, bottom
    )
    model = build_model(nodes, tets, mats)
    targets = _observed_motion(model, basis, conditions, known, top)
    moving = nodes[top][np.linalg.norm(targets[1], axis=1) > 0.01 * np.abs(targets).max()]
    gap = np.linalg.norm(basis.centres[:, None] - moving[None], axis=2).min(axis=1)
    far = gap >= 0.03
    assert far.sum() >= 3
    weights = np.ones((2, len(top)))
    fit = fit_actuation(model, basis, conditions, top, targets, weights, 3e-9, 3e-9)
    size = np.linalg.norm(fit.coefficients[1], axis=1)
    print("far patches' stress / largest:", size[far].max() / size.max())
    assert size[far].max() < 0.01 * size.max()
    misfit = np.linalg.norm(fit.fitted - targets) / np.linalg.norm(targets)
    assert misfit < 0.1  # and the fit still follows the motion


@pytest.mark.parametrize("vary", [False, True])
@pytest.mark.parametrize("anchored", [False, True])
@pytest.mark.parametrize("factors", [False, True])
def test_the_least_squares_over_frames_solve_the_normal_equations(vary, anchored, factors):
    """Against the stacked normal equations solved directly: frame-mean weights make the
    preconditioner exact to single precision (its start within 1e-5 of the answer, one or two
    iterations to 1e-12; also with stress cost factors that vary over the coefficients),
    weights that vary over frames take more; with ``anchored`` the frames follow one held at
    zero (its step to the first one counts)."""
    rng = np.random.default_rng(3)
    n_obs, n, n_frames = 12, 7, 6
    R = rng.normal(size=(3 * n_obs, n)) * 1e-6
    y = rng.normal(size=(n_frames, 3 * n_obs)) * 1e-3
    w = rng.uniform(0.2, 1.0, (n_frames, n_obs)) if vary else np.ones((n_frames, n_obs))
    v = rng.uniform(0.5, 2.0, n)
    v /= v.sum()
    lam, mu = (3e-5) ** 2, (1e-4) ** 2
    f = rng.uniform(1.0, 25.0, n) if factors else np.ones(n)
    ls = LeastSquares(R, v, 3e-5, 1e-4, w.mean(axis=0), n_frames, anchored, f)
    a, iterations = ls.solve(y, w, rtol=1e-12)
    start, _ = ls.solve(y, w, max_iter=0)
    assert 0 < iterations <= 2 if not vary else iterations > 2
    A = np.zeros((n_frames * n, n_frames * n))
    b = np.zeros(n_frames * n)
    diff = np.diff(np.eye(n_frames + anchored), axis=0)[:, int(anchored) :]
    lap = diff.T @ diff
    assert lap[0, 0] == 1 + anchored and lap[-1, -1] == 1
    for t in range(n_frames):
        wt = np.repeat(w[t] / w[t].sum(), 3)
        block = slice(t * n, (t + 1) * n)
        A[block, block] += R.T @ (wt[:, None] * R) + lam * np.diag(f * v)
        b[block] = R.T @ (wt * y[t])
        for s in range(n_frames):
            A[block, s * n : (s + 1) * n] += mu * lap[t, s] * np.diag(v)
    direct = np.linalg.solve(A, b).reshape(n_frames, n)
    np.testing.assert_allclose(a, direct, rtol=1e-7, atol=1e-9 * np.abs(direct).max())
    if not vary:
        assert np.linalg.norm(start - direct) < 1e-5 * np.linalg.norm(direct)


def test_the_robust_fit_does_not_chase_a_node_the_conditions_contradict():
    """One observed node's target off by 3 times the motion (as where the turning jaw drags
    tissue the capture holds): the least-squares fit bends the whole actuation towards it, the
    Huber fit (scale 5 % of the motion) leaves it and recovers the true actuation several
    times more closely."""
    nodes, tets, bottom, top, _ = _slab((4, 4, 2), (0.04, 0.04, 0.01))
    mats = TetMaterials.uniform(len(tets))
    basis = StressBasis.covering(nodes, tets, 0.018)
    known = np.zeros((2, basis.n_patches, 5))
    known[1] = np.random.default_rng(5).normal(size=(basis.n_patches, 5)) * 2e3
    conditions = BoundaryConditions.checked(
        len(nodes), np.zeros(0, np.int64), np.zeros((2, 0, 3)), 10.0, bottom
    )
    model = build_model(nodes, tets, mats)
    targets = _observed_motion(model, basis, conditions, known, top)
    scale = np.abs(targets).max()
    targets[1, 7, 2] += 3 * scale  # the contradicted node
    weights = np.ones((2, len(top)))
    errors = {}
    for robust in (0.0, 0.05 * scale):
        fit = fit_actuation(model, basis, conditions, top, targets, weights, 1e-10, 0.0,
                            robust=robust)  # fmt: skip
        errors[robust > 0] = np.linalg.norm(fit.coefficients - known) / np.linalg.norm(known)
    print("relative coefficient error, least squares / Huber:", errors)
    assert errors[True] < errors[False] / 5


def test_a_patch_cost_holds_its_patches_and_a_uniform_one_is_the_stress_cost_times_it():
    """``patch_cost``: every patch's cost times 3 is the fit at three times the stress cost
    (to round-off; the rate cost stays); three patches at 30 times the cost carry less than
    half the stress they carry at the plain cost."""
    nodes, tets, bottom, top, _ = _slab((4, 4, 2), (0.04, 0.04, 0.01))
    mats = TetMaterials.uniform(len(tets))
    basis = StressBasis.covering(nodes, tets, 0.018)
    known = np.zeros((3, basis.n_patches, 5))
    known[1:] = np.random.default_rng(7).normal(size=(2, basis.n_patches, 5)) * 2e3
    conditions = BoundaryConditions.checked(
        len(nodes), np.zeros(0, np.int64), np.zeros((3, 0, 3)), 10.0, bottom
    )
    model = build_model(nodes, tets, mats)
    targets = _observed_motion(model, basis, conditions, known, top)
    weights = np.ones((3, len(top)))
    costs = (3e-9, 1e-9)

    def fit(scale, patch_cost=None):
        return fit_actuation(model, basis, conditions, top, targets, weights,
                             scale * costs[0], costs[1], patch_cost=patch_cost)  # fmt: skip

    uniform = fit(1.0, np.full(basis.n_patches, 3.0))
    np.testing.assert_allclose(uniform.coefficients, fit(3.0).coefficients, rtol=1e-6,
                               atol=1e-6 * np.abs(uniform.coefficients).max())  # fmt: skip
    held = np.zeros(basis.n_patches, bool)
    held[:3] = True
    plain, stiff = fit(1.0), fit(1.0, np.where(held, 30.0, 1.0))
    size = lambda f: np.linalg.norm(f.coefficients[:, held])  # noqa: E731
    print("held patches' stress, plain / 30 times the cost:", size(plain), size(stiff))
    assert size(stiff) < 0.5 * size(plain)
    with pytest.raises(ValueError, match="patch_cost"):
        fit(1.0, np.zeros(basis.n_patches))
