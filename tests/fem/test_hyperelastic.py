"""The large-strain law (isochoric neo-Hookean, averaged nodal pressure on ln J, the actuation
as an active stress in the material frame or an active strain) against the linear 'anp' model
at rest, finite differences, and the analytic homogeneous uniaxial stretch under a dead load
(in tension, and in a compression that turns the linear model inside out), under a uniform
active stress, and under a uniform active strain (the tissue takes its shape exactly)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.optimize import fsolve

from physanim.fem.actuation import DEVIATORIC, StressBasis, model_force_operator
from physanim.fem.hyperelastic import NeoHookeanANP, NotConverged, solve_static_large_strain
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.params import ModelParams
from physanim.fem.statics import solve_static
from tests.fem.fem_meshes import box_mesh

E, NU, SIDE = 10e3, 0.45, 0.01  # Pa, -, m
MU, KAPPA = E / (2 * (1 + NU)), E / (3 * (1 - 2 * NU))


def _law(shape=(2, 2, 2), actuation: str = "stress") -> NeoHookeanANP:
    nodes, tets = box_mesh(shape, (SIDE,) * 3)
    mat = TetMaterials.uniform(len(tets), E=E, nu=NU, eta=1.0, rho=1000.0)
    model = build_model(nodes, tets, mat, ModelParams(formulation="anp"))
    return NeoHookeanANP(model, actuation)


def _stretched(law: NeoHookeanANP, rng: np.random.Generator) -> np.ndarray:
    """A smooth large deformation (stretches 0.7-1.4) with every tet right side out."""
    x = law.model.nodes / SIDE
    A = np.array([[0.3, 0.2, 0.0], [-0.1, -0.25, 0.15], [0.05, 0.1, 0.2]])
    d = SIDE * (x @ A.T + 0.05 * np.sin(3 * x[:, ::-1]))
    return d.ravel() + 1e-5 * SIDE * rng.normal(size=d.size)


def test_small_strain_is_the_linear_anp_model():
    law = _law()
    d = 1e-7 * SIDE * np.random.default_rng(0).normal(size=law.model.n_dofs)
    g, H = law.gradient(d, hessian=True)
    Kd = law.model.K @ d
    assert np.linalg.norm(g - Kd) <= 1e-5 * np.linalg.norm(Kd)
    rest = law.gradient(np.zeros_like(d), hessian=True)[1]
    assert abs(rest - law.model.K).max() <= 1e-9 * abs(law.model.K).max()


def test_small_strain_active_stress_is_the_linear_models():
    law = _law()
    sigma = 1e3 * np.random.default_rng(2).normal(size=(len(law.model.tets), 6))
    g, _ = law.gradient(np.zeros(law.model.n_dofs), active=sigma)
    assert g == pytest.approx(model_force_operator(law.model) @ sigma.ravel(), rel=1e-12)
    basis = StressBasis.covering(law.model.nodes, law.model.tets, SIDE / 2)
    rest = law.nominal_per_direction(np.zeros(law.model.n_dofs))
    assert abs(basis.force_matrix(law.model, rest) - basis.force_matrix(law.model)).max() < 1e-15


def test_small_active_strain_is_the_linear_models_active_stress():
    """An active strain of 1e-4 shear moduli pulls the rest like the linear model's active
    stress of the same Pa (to first order), per tet and per coefficient."""
    law = _law(actuation="strain")
    rng = np.random.default_rng(2)
    sigma = 1e-4 * MU * rng.normal(size=(len(law.model.tets), 5)) @ DEVIATORIC
    linear = -model_force_operator(law.model) @ sigma.ravel()
    g = law.active_forces(np.zeros(law.model.n_dofs), sigma)
    assert np.linalg.norm(g - linear) <= 1e-3 * np.linalg.norm(linear)
    basis = StressBasis.covering(law.model.nodes, law.model.tets, SIDE / 2)
    rest = law.nominal_per_direction(np.zeros(law.model.n_dofs), sigma)
    small = basis.force_matrix(law.model)
    assert abs(basis.force_matrix(law.model, rest) - small).max() <= 1e-3 * abs(small).max()


@pytest.mark.parametrize("actuation", [None, "stress", "strain"])
def test_gradient_and_hessian_match_finite_differences(actuation):
    rng = np.random.default_rng(1)
    law = _law(actuation=actuation or "stress")
    d = _stretched(law, rng)
    active = 2e3 * rng.normal(size=(len(law.model.tets), 6)) if actuation else None
    assert law.deformation(d)[1].min() > 0.3
    g, H = law.gradient(d, active=active, hessian=True)
    v, h = rng.normal(size=d.size) * SIDE * 1e-2, 1e-4
    slope = (law.energy(d + h * v, None, active) - law.energy(d - h * v, None, active)) / (2 * h)
    assert slope == pytest.approx(g @ v, rel=1e-6)
    grad = lambda x: law.gradient(x, active=active)[0]  # noqa: E731
    curvature = (grad(d + h * v) - grad(d - h * v)) / (2 * h)
    assert np.linalg.norm(curvature - H @ v) <= 1e-6 * np.linalg.norm(curvature)


def test_active_forces_turn_with_the_tissue_and_are_linear_in_the_coefficients():
    """Rotated rigidly, the tissue's active forces rotate with it (a stress held in the rest
    frame would not); the forces per coefficient at a deformed state are the gradient's."""
    rng = np.random.default_rng(3)
    law = _law()
    basis = StressBasis.covering(law.model.nodes, law.model.tets, SIDE / 2)
    c = 1e3 * rng.normal(size=(basis.n_patches, 5))
    c0, s, x = np.cos(0.6), np.sin(0.6), law.model.nodes
    R = np.array([[c0, -s, 0.0], [s, c0, 0.0], [0.0, 0.0, 1.0]])
    turned = (x @ R.T - x).ravel()
    at_rest = law.gradient(np.zeros(turned.size), active=basis.stress(c))[0].reshape(-1, 3)
    g = law.gradient(turned, active=basis.stress(c))[0].reshape(-1, 3)
    assert g == pytest.approx(at_rest @ R.T, abs=1e-9 * abs(at_rest).max())
    d = _stretched(law, rng)
    slope = law.gradient(d, active=basis.stress(c))[0] - law.gradient(d)[0]
    forces = basis.force_matrix(law.model, law.nominal_per_direction(d))
    assert -slope == pytest.approx(forces @ c.ravel(), rel=1e-9)
    assert law.active_forces(d, basis.stress(c)) == pytest.approx(-slope, rel=1e-12)


def test_active_strain_forces_per_coefficient_match_finite_differences():
    """At a large deformation and a large active strain (coefficients of order the shear
    modulus), the forces per coefficient are the derivative of the active forces."""
    rng = np.random.default_rng(4)
    law = _law(actuation="strain")
    basis = StressBasis.covering(law.model.nodes, law.model.tets, SIDE / 2)
    c = MU * rng.normal(size=(basis.n_patches, 5))
    d = _stretched(law, rng)
    forces = basis.force_matrix(law.model, law.nominal_per_direction(d, basis.stress(c)))
    dc, h = rng.normal(size=c.shape), 1e-3 * MU
    fd = (law.active_forces(d, basis.stress(c + h * dc))
          - law.active_forces(d, basis.stress(c - h * dc))) / (2 * h)  # fmt: skip
    assert np.linalg.norm(fd - forces @ dc.ravel()) <= 1e-6 * np.linalg.norm(fd)


def test_energy_is_infinite_once_a_tet_turns_inside_out():
    law = _law()
    nodes = law.model.nodes
    flat = np.zeros_like(nodes)
    flat[:, 0] = -1.2 * nodes[:, 0]  # x -> -0.2 x: every tet mirrored
    assert law.energy(flat.ravel()) == np.inf
    assert np.isfinite(law.energy(0.5 * flat.ravel()))  # x -> 0.4 x


def _uniaxial(load: float, active: float = 0.0) -> tuple[float, float]:
    """Homogeneous stretches (axial, lateral) of the law's material under a nominal uniaxial
    dead load ``load`` Pa and an active stress ``active`` Pa along x, lateral nominal stress
    0."""

    def nominal(s):
        lam, lat = s
        F = np.diag([lam, lat, lat])
        J, FiT = lam * lat**2, np.diag([1 / lam, 1 / lat, 1 / lat])
        P = MU * J ** (-2 / 3) * (F - np.trace(F.T @ F) / 3 * FiT) + KAPPA * np.log(J) * FiT
        return [P[0, 0] + lam * active - load, P[1, 1]]

    guess = [1.4, 0.85] if load - active > 0 else [0.5, 1.4]
    return tuple(fsolve(nominal, guess, xtol=1e-13))


def _cube_under(load: float, law: NeoHookeanANP):
    """Symmetry planes x = 0, y = 0, z = 0 and the face x = SIDE pulled by ``load`` Pa
    (nominal): (prescribed DOFs, consistent nodal forces (3N,) N)."""
    nodes, tets = law.model.nodes, law.model.tets
    pres = np.concatenate([3 * np.flatnonzero(np.isclose(nodes[:, k], 0)) + k for k in range(3)])
    f = np.zeros(law.model.n_dofs)
    on_face = np.isclose(nodes[:, 0], SIDE)
    for tet in tets:  # each boundary triangle carries load x area, a third to each node
        face = tet[on_face[tet]]
        if len(face) == 3:
            p = nodes[face]
            area = 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))
            f[3 * face] += load * area / 3
    return np.sort(pres), f


@pytest.mark.parametrize("load", [3e3, -12e3])
def test_uniaxial_dead_load_gives_the_analytic_stretch(load):
    """Tension (stretch 1.4) and a compression at which the linear model's strain is -1.2:
    it turns the cube inside out, this law squeezes it to the analytic stretch 0.5."""
    law = _law()
    pres, f = _cube_under(load, law)
    lam, lat = _uniaxial(load)
    d = np.zeros(law.model.n_dofs)
    for step in np.linspace(0.25, 1.0, 4):  # load in steps, each from the last equilibrium
        d, _ = solve_static_large_strain(law, pres, np.zeros(len(pres)), step * f, start=d)
    u = d.reshape(-1, 3)
    nodes = law.model.nodes
    assert u[:, 0] == pytest.approx((lam - 1) * nodes[:, 0], abs=1e-6 * SIDE)
    assert u[:, 1] == pytest.approx((lat - 1) * nodes[:, 1], abs=1e-6 * SIDE)
    linear = solve_static(law.model.K, pres, np.zeros(len(pres)), f).reshape(-1, 3)
    at_face = np.isclose(nodes[:, 0], SIDE)
    assert abs(linear[at_face, 0].mean() / SIDE - (lam - 1)) > 0.1  # a linear law differs
    if load < 0:
        assert linear[at_face, 0].mean() < -SIDE and 0.4 < lam < 0.6


def test_a_uniform_active_stress_contracts_the_tissue_to_the_analytic_stretch():
    """A tensile active stress along x of 1.5 shear moduli (the linear model: strain -0.5)
    contracts the free cube (symmetry planes only) to the analytic stretch."""
    law = _law()
    pres, _ = _cube_under(0.0, law)
    stress = 1.5 * MU
    active = np.zeros((len(law.model.tets), 6))
    active[:, 0] = stress
    d = np.zeros(law.model.n_dofs)
    for step in np.linspace(0.25, 1.0, 4):
        d, _ = solve_static_large_strain(
            law, pres, np.zeros(len(pres)), active=step * active, start=d
        )
    lam, lat = _uniaxial(0.0, stress)
    u = d.reshape(-1, 3)
    assert u[:, 0] == pytest.approx((lam - 1) * law.model.nodes[:, 0], abs=1e-6 * SIDE)
    assert u[:, 1] == pytest.approx((lat - 1) * law.model.nodes[:, 1], abs=1e-6 * SIDE)
    assert 0.55 < lam < 0.75


def _shape_of(strain_along_x: float) -> NDArray:
    """The Voigt actuation (Pa) whose active strain is diag(e, -e/2, -e/2), e the argument."""
    out = np.zeros(6)
    out[:3] = -2 * MU * strain_along_x * np.array([1.0, -0.5, -0.5])
    return out


def test_a_uniform_active_strain_gives_the_tissue_its_shape():
    """Actuated by a uniform active strain that shortens it to a quarter along x, the free
    cube (symmetry planes only) takes the shape F_a = expm(eps_a) exactly, stress free; the
    same actuation as an active stress (1.4 shear moduli of compression across x) has no
    equilibrium."""

    def loaded(law, pres, active):  # in four steps of the actuation
        d = np.zeros(law.model.n_dofs)
        for step in np.linspace(0.25, 1.0, 4):
            d, _ = solve_static_large_strain(
                law, pres, np.zeros(len(pres)), active=step * active, start=d
            )
        return d

    for actuation in ("strain", "stress"):
        law = _law(actuation=actuation)
        pres, _ = _cube_under(0.0, law)
        e = np.log(0.25)
        active = np.tile(_shape_of(e), (len(law.model.tets), 1))
        if actuation == "stress":
            assert active[0, 1] < -MU  # beyond the active stress's limit
            with pytest.raises(NotConverged):
                loaded(law, pres, active)
            continue
        d = loaded(law, pres, active)
        stretch = np.exp([e, -e / 2, -e / 2])
        assert d.reshape(-1, 3) == pytest.approx((stretch - 1) * law.model.nodes, abs=1e-6 * SIDE)
        F, _ = law.deformation(d)  # the elastic part F F_a^-1 is the identity: no stress
        assert abs(F @ np.diag(1 / stretch) - np.eye(3)).max() < 1e-6
