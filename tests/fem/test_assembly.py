"""Element matrices and their assembly against closed forms and a dense reference."""

import numpy as np
from fem_meshes import box_mesh

from physanim.fem.assembly import assemble, element_blocks, mass_matrix, strain_displacement
from physanim.fem.geometry import shape_gradients


def test_element_blocks_are_v_bt_d_b():
    nodes, tets = box_mesh((2, 2, 2), (0.01, 0.01, 0.01))
    grads, volumes = shape_gradients(nodes, tets)
    D = np.random.default_rng(0).normal(size=(len(tets), 6, 6))  # any, not even symmetric
    B = strain_displacement(grads)
    expected = np.einsum("mia,mij,mjb,m->mab", B, D, B, volumes)
    np.testing.assert_allclose(element_blocks(grads, volumes, D), expected, rtol=1e-12,
                               atol=1e-12 * np.abs(expected).max())  # fmt: skip


def test_consistent_mass_is_the_closed_form_and_weighs_the_body():
    nodes, tets = box_mesh((3, 2, 2), (0.03, 0.02, 0.02))
    _, volumes = shape_gradients(nodes, tets)
    rho = np.linspace(900.0, 1100.0, len(tets))
    M = mass_matrix(tets, volumes, rho, len(nodes), lumped=False)
    # rho V / 20 (1 + [a == b]) on each node pair's diagonal DOF pairs, assembled
    blocks = (rho * volumes)[:, None, None] * np.kron(np.ones((4, 4)) + np.eye(4), np.eye(3))
    np.testing.assert_allclose(
        M.toarray(), assemble(blocks / 20.0, tets, len(nodes)).toarray(), rtol=1e-13, atol=0
    )
    for axis in range(3):  # a rigid translation's kinetic form is the body's mass
        u = np.zeros((len(nodes), 3))
        u[:, axis] = 1.0
        assert np.isclose(u.ravel() @ M @ u.ravel(), rho @ volumes, rtol=1e-13, atol=0)
