"""A new constitutive law plugs in without editing the library: defined here, passed to
``build_model(law=...)`` and run through ``simulate(model=...)``, against analytic answers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from fem_meshes import box_mesh

from physanim.fem.assembly import deviatoric_matrix, lame, volumetric_matrix
from physanim.fem.geometry import node_dofs
from physanim.fem.laws import MaterialLaw
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.params import SimulateParams
from physanim.fem.simulate import simulate
from physanim.fem.statics import reactions, solve_static


@dataclass(frozen=True)
class StiffnessProportional(MaterialLaw):
    """Linear elastic, scaled by ``scale``, with stiffness-proportional (Rayleigh) damping
    C' = beta C (s) instead of Kelvin-Voigt's deviatoric eta: the whole new law."""

    beta: float
    scale: float = 1.0

    def moduli(self, mat: TetMaterials) -> tuple[np.ndarray, np.ndarray]:
        mu, kappa = lame(mat.E, mat.nu)
        return self.scale * mu, self.scale * kappa

    def viscosity(self, mat: TetMaterials) -> np.ndarray:
        mu, kappa = self.moduli(mat)
        return self.beta * (deviatoric_matrix(mu) + volumetric_matrix(kappa))


def test_scaled_law_stretches_a_bar_as_hooke_says():
    """A bar (nu = 0, length L, section A) clamped at z = 0 and stretched by u0 at z = L pulls
    back with F = scale E A u0 / L (exact for linear tets: the strain is uniform)."""
    length, side, e_pa, u0, scale = 0.04, 0.01, 3e4, 1e-4, 2.5
    nodes, tets = box_mesh((2, 2, 4), (side, side, length))
    mat = TetMaterials.uniform(len(tets), e_pa, 0.0, 10.0, 1000.0)
    law = StiffnessProportional(beta=0.0, scale=scale)
    model = build_model(nodes, tets, mat, SimulateParams(formulation="p1"), law=law)
    bottom = node_dofs(np.flatnonzero(nodes[:, 2] == 0))
    top_nodes = np.flatnonzero(np.isclose(nodes[:, 2], length))
    top_z = 3 * top_nodes + 2
    prescribed = np.concatenate([bottom, top_z])
    values = np.r_[np.zeros(len(bottom)), np.full(len(top_z), u0)]
    d = solve_static(model.K, prescribed, values)
    force = reactions(model.K, d)[top_z].sum()
    np.testing.assert_allclose(force, scale * e_pa * side**2 * u0 / length, rtol=1e-9)
    # the default law (Kelvin-Voigt) is the same elasticity at scale 1
    default = build_model(nodes, tets, mat, SimulateParams(formulation="p1"))
    np.testing.assert_allclose((model.K - scale * default.K).data, 0, atol=1e-9 * e_pa)


def test_rayleigh_damping_decays_the_first_mode_at_beta_omega_squared_over_two():
    """A block clamped at its base, one top corner pushed and held: the first mode of the
    free DOFs rings down at sigma = beta omega_1^2 / 2 (classical damping, C = beta K)."""
    nodes, tets = box_mesh((2, 2, 3), (0.02, 0.015, 0.03))
    mat = TetMaterials.uniform(len(tets), 2e4, 0.3, 0.0, 1000.0)
    params = SimulateParams(formulation="p1", stepping="fixed")
    fixed = np.flatnonzero(nodes[:, 2] == 0)
    corner = np.flatnonzero((nodes == nodes.max(axis=0)).all(axis=1))
    free = np.setdiff1d(np.arange(3 * len(nodes)), node_dofs(np.r_[fixed, corner]))
    undamped = build_model(nodes, tets, mat, params, law=StiffnessProportional(beta=0.0))
    k_uu = undamped.K[free][:, free].toarray()
    m_uu = undamped.M[free][:, free].toarray()
    w2, modes = sla.eigh(k_uu, m_uu, subset_by_index=(0, 0))
    omega = float(np.sqrt(w2[0]))
    beta = 2 * 0.03 / omega  # damping ratio 0.03 in the first mode
    model = build_model(nodes, tets, mat, params, law=StiffnessProportional(beta=beta))
    np.testing.assert_allclose(model.C.toarray(), beta * model.K.toarray(), atol=1e-12 * beta)

    frame_dt = 2 * np.pi / omega / 16
    n_frames, ramp = 80, 4
    push = (
        1e-3
        * np.clip(np.arange(n_frames) / ramp, 0, 1)[:, None, None]
        * np.array([[[1.0, 0.0, 0.0]]])
    )
    res = simulate(nodes, tets, mat, corner, push, frame_dt, fixed, params.model_copy(
        update={"dt": frame_dt / 8}), model=model)  # fmt: skip
    held = node_dofs(np.r_[corner, fixed])
    rest = solve_static(model.K, held, np.r_[push[-1].ravel(), np.zeros(3 * len(fixed))])
    d = res.displacements.reshape(n_frames, -1)[:, free] - rest[free]
    q = d @ m_uu @ modes[:, 0]  # first-mode coordinate about the held state
    q = q[ramp + 2 :]
    # a damped mode sampled every h obeys q[k+1] = a1 q[k] + a2 q[k-1], a2 = -exp(-2 sigma h)
    (a1, a2), *_ = np.linalg.lstsq(np.column_stack([q[1:-1], q[:-2]]), q[2:], rcond=None)
    sigma = -np.log(-a2) / (2 * frame_dt)
    np.testing.assert_allclose(sigma, beta * omega**2 / 2, rtol=0.01)
    omega_d = np.arccos(a1 / (2 * np.sqrt(-a2))) / frame_dt
    np.testing.assert_allclose(omega_d, omega * np.sqrt(1 - 0.03**2), rtol=0.01)
