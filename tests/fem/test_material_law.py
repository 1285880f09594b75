"""A new constitutive law plugs in without editing the library: one class with its schema,
defined and registered here, chosen by name from a YAML config (its per-tet field ``beta_s``
given in the materials file's ``fields``) and run through ``simulate``, against analytic
answers."""

from __future__ import annotations

from typing import ClassVar, Literal

import numpy as np
import pytest
import scipy.linalg as sla
import yaml
from fem_meshes import box_mesh
from pydantic import Field

from physanim.config import load_config
from physanim.fem.assembly import deviatoric_matrix, lame, volumetric_matrix
from physanim.fem.geometry import node_dofs
from physanim.fem.laws import MaterialLaw, register_law
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.params import SimulateParams
from physanim.fem.region_materials import tet_materials
from physanim.fem.simulate import simulate
from physanim.fem.statics import reactions, solve_static


@register_law
class StiffnessProportional(MaterialLaw):
    """Linear elastic, scaled by ``scale``, with stiffness-proportional (Rayleigh) damping
    C' = beta C, beta (s) per tet, instead of Kelvin-Voigt's deviatoric eta."""

    name: Literal["stiffness_proportional"] = "stiffness_proportional"
    scale: float = Field(1.0, gt=0.0, description="factor on the elastic moduli (dimensionless)")
    tet_fields: ClassVar[tuple[str, ...]] = ("E", "nu", "rho", "beta_s")

    def moduli(self, mat: TetMaterials) -> tuple[np.ndarray, np.ndarray]:
        mu, kappa = lame(mat.E, mat.nu)
        return self.scale * mu, self.scale * kappa

    def viscosity(self, mat: TetMaterials) -> np.ndarray:
        mu, kappa = self.moduli(mat)
        beta = mat["beta_s"][:, None, None]
        return beta * (deviatoric_matrix(mu) + volumetric_matrix(kappa))


def test_scaled_law_stretches_a_bar_as_hooke_says():
    """A bar (nu = 0, length L, section A) clamped at z = 0 and stretched by u0 at z = L pulls
    back with F = scale E A u0 / L (exact for linear tets: the strain is uniform)."""
    length, side, e_pa, u0, scale = 0.04, 0.01, 3e4, 1e-4, 2.5
    nodes, tets = box_mesh((2, 2, 4), (side, side, length))
    mat = TetMaterials.uniform(len(tets), e_pa, 0.0, 10.0, 1000.0, beta_s=0.0)
    law = StiffnessProportional(scale=scale)
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


LAW_CONFIG = """
simulate: {law: {name: stiffness_proportional}, formulation: p1, stepping: fixed}
materials:
  model:
    name: rayleigh
    default: {E_kPa: 20.0, nu: 0.3, eta_Pa_s: 0.0, rho_kg_m3: 1000.0, fields: {beta_s: 0.0}}
"""


def _from_config(tmp_path, beta: float):
    """The face pipeline's simulate params and materials model from the YAML a user writes
    (``-c law.yaml`` over the default config), with ``beta_s`` set for the whole tissue."""
    from flows.dags import FACE

    text = LAW_CONFIG.replace("beta_s: 0.0", f"beta_s: {beta!r}")
    (tmp_path / "law.yaml").write_text(text)
    config, _ = load_config(FACE.config_model(), [FACE.default_config, tmp_path / "law.yaml"])
    return config.simulate, config.materials.model


def test_rayleigh_damping_decays_the_first_mode_at_beta_omega_squared_over_two(tmp_path):
    """The law chosen in YAML: a block clamped at its base, one top corner pushed and held:
    the first mode of the free DOFs rings down at sigma = beta omega_1^2 / 2 (classical
    damping, C = beta K), beta given per tet by the materials file."""
    nodes, tets = box_mesh((2, 2, 3), (0.02, 0.015, 0.03))
    labels = np.zeros(len(tets), dtype=np.int64)  # every tet in the default region
    params, model_file = _from_config(tmp_path, 0.0)
    assert isinstance(params.law, StiffnessProportional)
    mat = tet_materials(labels, model_file)
    np.testing.assert_array_equal(mat["beta_s"], 0.0)
    fixed = np.flatnonzero(nodes[:, 2] == 0)
    corner = np.flatnonzero((nodes == nodes.max(axis=0)).all(axis=1))
    free = np.setdiff1d(np.arange(3 * len(nodes)), node_dofs(np.r_[fixed, corner]))
    undamped = build_model(nodes, tets, mat, params)
    k_uu = undamped.K[free][:, free].toarray()
    m_uu = undamped.M[free][:, free].toarray()
    w2, modes = sla.eigh(k_uu, m_uu, subset_by_index=(0, 0))
    omega = float(np.sqrt(w2[0]))
    beta = 2 * 0.03 / omega  # damping ratio 0.03 in the first mode
    params, model_file = _from_config(tmp_path, beta)
    mat = tet_materials(labels, model_file)
    model = build_model(nodes, tets, mat, params)
    np.testing.assert_allclose(model.C.toarray(), beta * model.K.toarray(), atol=1e-12 * beta)

    frame_dt = 2 * np.pi / omega / 16
    n_frames, ramp = 80, 4
    push = (
        1e-3
        * np.clip(np.arange(n_frames) / ramp, 0, 1)[:, None, None]
        * np.array([[[1.0, 0.0, 0.0]]])
    )
    step = params.model_copy(update={"dt": frame_dt / 8})
    res = simulate(nodes, tets, mat, corner, push, frame_dt, fixed, step)
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


def test_a_law_refuses_materials_without_its_fields_and_a_config_an_unknown_law(tmp_path):
    """The law's per-tet field missing from the materials: the error names it; an unknown
    law name or setting in YAML: the config error names the registered laws / the field."""
    from flows.dags import FACE
    from physanim.config import ConfigError

    nodes, tets = box_mesh((1, 1, 1), (0.01, 0.01, 0.01))
    with pytest.raises(ValueError, match=r"lack the per-tet field\(s\) \['beta_s'\]"):
        build_model(nodes, tets, TetMaterials.uniform(len(tets)), law=StiffnessProportional())
    _, model_file = _from_config(tmp_path, 1e-3)
    cheek = model_file.default.model_copy(update={"fields": {"beta_s": 2e-3, "gamma_s": 1.0}})
    regional = model_file.model_copy(update={"regions": {"Cheek": cheek}})
    np.testing.assert_array_equal(tet_materials(np.array([0, 1]), model_file)["beta_s"], 1e-3)
    stiffer = model_file.model_copy(update={"regions": {"Cheek": cheek.model_copy(
        update={"fields": {"beta_s": 2e-3}})}})  # fmt: skip
    np.testing.assert_array_equal(tet_materials(np.array([0, 1]), stiffer)["beta_s"], [1e-3, 2e-3])
    with pytest.raises(ValueError, match=r"region Cheek gives fields \['gamma_s'\]"):
        tet_materials(np.array([0, 1]), regional)
    for law, said in (("{name: nope}", "registered laws: .*stiffness_proportional"),
                      ("{name: stiffness_proportional, scale: -1}", "scale")):  # fmt: skip
        (tmp_path / "bad.yaml").write_text(
            yaml.safe_dump({"simulate": {"law": yaml.safe_load(law)}})
        )
        with pytest.raises(ConfigError, match=said):
            load_config(FACE.config_model(), [FACE.default_config, tmp_path / "bad.yaml"])
