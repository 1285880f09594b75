"""Active stress (physanim.fem.actuation): patch test, Kelvin-Voigt creep, basis, forces."""

import numpy as np
import pytest
from fem_meshes import box_mesh

from physanim.fem.actuation import (
    DEEP_REACH_PER_SPACING,
    DEVIATORIC,
    SEAM_LIFT_PER_SPACING,
    Actuation,
    StressBasis,
    covering_centres,
    model_force_operator,
    seam_lift,
)
from physanim.fem.assembly import deviatoric_matrix, lame, strain_displacement, volumetric_matrix
from physanim.fem.boundary import FrameForce
from physanim.fem.geometry import node_dofs, signed_volumes
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.params import SimulateParams
from physanim.fem.problem import FemProblem
from physanim.fem.simulate import simulate_problem
from physanim.fem.statics import solve_static

SIZE = np.array([0.02, 0.03, 0.01])


def _block(seed: int = 0):
    """An irregular box mesh (interior nodes jittered) and its 3-2-1 support: the six DOFs
    that stop rigid motion and nothing else."""
    rng = np.random.default_rng(seed)
    nodes, tets = box_mesh((3, 3, 2), tuple(SIZE))
    inner = np.all((nodes > 1e-9) & (nodes < SIZE - 1e-9), axis=1)
    nodes[inner] += rng.uniform(-1e-3, 1e-3, (inner.sum(), 3)) * [0.6, 0.6, 0.3]
    assert (signed_volumes(nodes, tets) > 0).all()
    corner = lambda p: int(np.argmin(np.linalg.norm(nodes - p, axis=1)))  # noqa: E731
    a, b, c = corner([0, 0, 0]), corner([SIZE[0], 0, 0]), corner([0, SIZE[1], 0])
    support = np.r_[node_dofs(np.array([a])), 3 * b + 1, 3 * b + 2, 3 * c + 2]
    return nodes, tets, support


def _strains(model, d):
    """Per-tet engineering strains (M, 6) of displacements d (3N,)."""
    return np.einsum("mij,mj->mi", strain_displacement(model.grads), d[model.dofs])


def _whole(nodes, tets) -> StressBasis:
    """One patch over the whole mesh: a uniform stress field."""
    return StressBasis.patches(nodes, tets, nodes.mean(axis=0)[None], 1.0)


@pytest.mark.parametrize("formulation", ["anp", "p1"])
def test_uniform_active_stress_gives_the_uniform_strain_minus_c_inverse_sigma(formulation):
    """Patch test: a block held only against rigid motion under a uniform active stress
    (deviatoric and volumetric parts) settles at eps = -C^{-1} sigma_a in every tet, its
    total stress C eps + sigma_a zero, with the default element ('anp') and the plain one."""
    nodes, tets, support = _block()
    E, nu = 1e5, 0.45
    model = build_model(nodes, tets, TetMaterials.uniform(len(tets), E=E, nu=nu),
                        SimulateParams(formulation=formulation))  # fmt: skip
    sigma = np.array([3e3, -1e3, 2e3, 5e2, -7e2, 1.2e3])  # Pa, Voigt
    f = -(model_force_operator(model) @ np.tile(sigma, len(tets)))
    d = solve_static(model.K, support, np.zeros(len(support)), f)
    mu, kappa = lame(np.array([E]), np.array([nu]))
    C = (deviatoric_matrix(mu) + volumetric_matrix(kappa))[0]
    expected = -np.linalg.solve(C, sigma)
    strains = _strains(model, d)
    np.testing.assert_allclose(strains, np.broadcast_to(expected, strains.shape),
                               rtol=0, atol=1e-10 * np.abs(expected).max())  # fmt: skip
    np.testing.assert_allclose(strains @ C.T + sigma, 0.0, atol=1e-9 * np.abs(sigma).max())


def test_kelvin_voigt_tissue_creeps_behind_a_ramped_actuation_by_eta_over_mu():
    """A deviatoric active stress ramped linearly over the frames (Catmull-Rom reproduces
    the ramp) strains the block as tau eps' + eps = -C^{-1} sigma_a(t), tau = eta / mu:
    eps(t) = -C^{-1} (sigma_0 / t_r) (t - tau (1 - exp(-t / tau))) (inertia negligible:
    the block's slowest elastic mode is overdamped 20 times over). The block floats free:
    the active forces have no resultant, and its mass makes each Newmark step well posed."""
    nodes, tets, _ = _block(1)
    E, nu, tau, frame_dt, n_frames = 1e4, 0.45, 0.05, 0.01, 16
    mu = E / (2 * (1 + nu))
    mats = TetMaterials.uniform(len(tets), E=E, nu=nu, eta=tau * mu, rho=1000.0)
    c0 = np.array([400.0, -150.0, 300.0, 200.0, -100.0])  # Pa at t_r
    sigma0 = c0 @ DEVIATORIC
    t = frame_dt * np.arange(n_frames)
    t_r = t[-1]
    coefficients = (t / t_r)[:, None, None] * c0[None, None, :]
    actuation = Actuation(_whole(nodes, tets), coefficients)
    problem = FemProblem.driven(nodes, tets, mats, np.zeros(0, np.int64),
                                np.zeros((n_frames, 0, 3)), frame_dt)  # fmt: skip
    params = SimulateParams(dt=1e-4, stepping="fixed", precision="float64")
    run = simulate_problem(problem.with_actuation(actuation), params)
    model = build_model(nodes, tets, mats, params)
    mean_strain = np.array([_strains(model, d.ravel().astype(float)).mean(axis=0)
                            for d in run.displacements])  # fmt: skip
    C = (deviatoric_matrix(np.array([mu])) + volumetric_matrix(np.array([E / 3 / (1 - 2 * nu)])))[0]
    creep = (t - tau * (1 - np.exp(-t / tau))) / t_r
    expected = -creep[:, None] * np.linalg.solve(C, sigma0)[None]
    scale = np.abs(expected).max()
    np.testing.assert_allclose(mean_strain, expected, atol=0.01 * scale)
    # the lag: at the end of the ramp the strain trails the static answer by tau / t_r
    static_end = -np.linalg.solve(C, sigma0)
    lag = 1 - mean_strain[-1] @ static_end / (static_end @ static_end)
    assert lag == pytest.approx(tau / t_r * (1 - np.exp(-t_r / tau)), rel=0.03)


def test_stress_basis_is_a_smooth_partition_of_unity_covering_the_mesh():
    nodes, tets = box_mesh((6, 4, 2), (0.06, 0.04, 0.01))
    spacing = 0.012
    basis = StressBasis.covering(nodes, tets, spacing)
    centroids = nodes[tets].mean(axis=1)
    dist = np.linalg.norm(centroids[:, None] - basis.centres[None], axis=2)
    assert dist.min(axis=1).max() <= spacing  # every tet within the spacing of a centre
    np.testing.assert_allclose(np.asarray(basis.weights.sum(axis=1)).ravel(), 1.0, rtol=1e-12)
    assert basis.weights.min() >= 0 and basis.n_patches > 4
    assert np.all(dist[basis.weights.toarray() > 0] < basis.radius)
    np.testing.assert_allclose(basis.patch_volumes(np.ones(len(tets))).sum(), len(tets))
    # the force matrix is the active force of the stress the coefficients make
    model = build_model(nodes, tets, TetMaterials.uniform(len(tets)))
    c = np.random.default_rng(2).normal(size=(basis.n_patches, 5)) * 1e3
    forces = basis.force_matrix(model) @ c.ravel()
    direct = -(model_force_operator(model) @ basis.stress(c).ravel())
    np.testing.assert_allclose(forces, direct, atol=1e-12 * np.abs(direct).max())
    # Actuation.force gives the same forces at each frame on the free DOFs asked for
    free = np.arange(0, model.n_dofs, 2)
    per_frame = Actuation(basis, np.stack([c, 2 * c, -c])).force(model, free, 0.1).values
    expected = np.stack([forces, 2 * forces, -forces])[:, free]
    np.testing.assert_allclose(per_frame, expected, atol=1e-12 * np.abs(direct).max())
    # an unloaded body is in equilibrium: active forces sum to zero force and moment
    f = forces.reshape(-1, 3)
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12 * np.abs(f).max())
    np.testing.assert_allclose(np.cross(nodes, f).sum(axis=0), 0.0, atol=1e-13 * np.abs(f).max())
    assert len(covering_centres(centroids, 1.0)) == 1


def test_centres_restricted_to_a_layer_still_cover_the_mesh():
    """Centres only on the eligible tets (a 'muscle layer' over the top 10 mm of a 30 mm
    block): each eligible tet within the spacing of a centre, every other within
    DEEP_REACH_PER_SPACING spacings of one, fewer patches than the unrestricted covering,
    and the weights still a partition of unity."""
    nodes, tets = box_mesh((6, 4, 6), (0.06, 0.04, 0.03))
    spacing = 0.008
    centroids = nodes[tets].mean(axis=1)
    layer = centroids[:, 2] > 0.02
    basis = StressBasis.covering(nodes, tets, spacing, eligible=layer)
    full = StressBasis.covering(nodes, tets, spacing)
    dist = np.linalg.norm(centroids[:, None] - basis.centres[None], axis=2).min(axis=1)
    assert dist[layer].max() <= spacing
    assert dist[~layer].max() <= DEEP_REACH_PER_SPACING * spacing
    assert dist[~layer].max() > spacing  # the deep tissue is not covered as finely
    on_layer = np.isin(basis.centres, centroids[layer]).all(axis=1)
    assert on_layer.sum() >= 0.8 * basis.n_patches
    assert basis.n_patches < 0.8 * full.n_patches
    np.testing.assert_allclose(np.asarray(basis.weights.sum(axis=1)).ravel(), 1.0, rtol=1e-12)
    # no eligible tet at all: the plain covering
    none = StressBasis.covering(nodes, tets, spacing, eligible=np.zeros(len(tets), bool))
    np.testing.assert_array_equal(none.centres, full.centres)


def test_lip_patches_never_span_the_seam_and_still_cover_the_mesh():
    """With the seam lift, a block split at mid-height into an 'upper lip' band above and a
    'lower lip' band below (sides 1 and -1 within 8 mm of the seam, 0 beyond): every patch
    weighs tets of one side only, each lip has patches of its own, and the weights stay a
    partition of unity; without it some patch spans the seam."""
    nodes, tets = box_mesh((6, 6, 2), (0.06, 0.06, 0.01))
    dy = nodes[:, 1] - 0.035
    side = np.where(np.abs(dy) < 0.008, np.sign(dy), 0).astype(np.int8)
    spacing = 0.012
    lift = seam_lift(tets, side, SEAM_LIFT_PER_SPACING * spacing)
    tet_side = np.sign(side[tets].sum(axis=1))
    assert (tet_side > 0).any() and (tet_side < 0).any()
    for lifted in (lift, None):
        basis = StressBasis.covering(nodes, tets, spacing, lifted)
        w = basis.weights.toarray() > 0
        sides = np.array([len(np.unique(tet_side[w[:, p]])) for p in range(basis.n_patches)])
        assert (sides == 1).all() if lifted is not None else (sides > 1).any()
        np.testing.assert_allclose(basis.weights.sum(axis=1), 1.0, rtol=1e-12)
    assert (basis.lift == 0).all()
    lipped = StressBasis.covering(nodes, tets, spacing, lift)
    assert (lipped.lift > 0).any() and (lipped.lift < 0).any()
    rebuilt = StressBasis.patches(nodes, tets, lipped.centres, lipped.radius, lift, lipped.lift)
    assert abs(rebuilt.weights - lipped.weights).max() < 1e-15


def test_frame_forces_add_on_the_union_of_their_dofs():
    a = FrameForce(np.array([[1.0, 2.0], [3.0, 4.0]]), np.array([3, 7]), np.array([0, 2]), 0.1, 4)
    b = FrameForce(np.array([[10.0], [20.0]]), np.array([7]), np.array([2]), 0.1, 4)
    c = FrameForce(np.array([[5.0], [6.0]]), np.array([5]), np.array([1]), 0.1, 4)
    total = a + b + c
    np.testing.assert_array_equal(total.dofs, [3, 5, 7])
    np.testing.assert_allclose(total.free(np.array([0.0, 0.1])), [[1, 5, 12, 0], [3, 6, 24, 0]])
    np.testing.assert_allclose(total.full(0.05, 8)[[3, 5, 7]], [2, 5.5, 18])
    with pytest.raises(ValueError, match="share"):
        a + FrameForce(np.zeros((3, 1)), np.array([1]), np.array([0]), 0.1, 4)


def test_actuation_shapes_are_checked():
    nodes, tets = box_mesh((2, 2, 1), (0.02, 0.02, 0.01))
    basis = _whole(nodes, tets)
    with pytest.raises(ValueError, match="coefficients"):
        Actuation(basis, np.zeros((4, 1, 6)))
    problem = FemProblem.driven(nodes, tets, TetMaterials.uniform(len(tets)), np.array([0]),
                                np.zeros((3, 1, 3)), 0.1)  # fmt: skip
    with pytest.raises(ValueError, match="frames"):
        problem.with_actuation(Actuation(basis, np.zeros((4, 1, 5))))


def test_scaling_by_patch_or_by_frame_and_patch():
    nodes, tets = box_mesh((2, 2, 1), (0.02, 0.02, 0.01))
    basis = _whole(nodes, tets)
    c = np.arange(3 * 5, dtype=float).reshape(3, 1, 5) + 1.0
    act = Actuation(basis, c)
    np.testing.assert_array_equal(act.scaled(np.array([2.0])).coefficients, 2.0 * c)
    per_frame = act.scaled(np.array([[1.0], [1.5], [0.0]])).coefficients
    np.testing.assert_array_equal(per_frame, c * np.array([1.0, 1.5, 0.0])[:, None, None])
