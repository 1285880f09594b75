"""Soft drives (springs towards moving targets) against analytic answers."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.fem.boundary import MIN_PATCH_NODES, SpringDrive, landmark_drive, patch_weights
from physanim.fem.materials import TetMaterials
from physanim.fem.params import SimulateParams
from physanim.fem.simulate import simulate
from physanim.mesh.tetra import boundary_faces
from physanim.mesh.topology import vertex_areas
from tests.mesh.test_seam import block


def test_springs_in_series_with_a_uniaxial_block() -> None:
    """A block (E, nu = 0, height L, area A) fixed at the bottom, its top nodes pulled up by
    springs to u0: the top settles at k_s u0 / (k_s + E A / L) (springs in series)."""
    nodes, tets = block(nx=5, ny=5, nz=5)  # 6 x 4 x 1 cm
    e_pa, area, height = 2e5, 0.06 * 0.04, 0.01
    k_block = e_pa * area / height
    bottom = np.nonzero(nodes[:, 2] < -0.0099)[0]
    top = np.nonzero(nodes[:, 2] > -1e-6)[0]
    # each top node's share of the top face (a third of its triangles): a uniform pull
    outer = boundary_faces(tets)
    share = vertex_areas(nodes, outer[np.isin(outer, top).all(axis=1)])[top]
    k_s = 3.0 * k_block
    u0 = 1e-3
    n_frames = 40
    ramp = u0 * np.clip(np.linspace(0, 2, n_frames), 0, 1)  # up, then held
    targets = np.zeros((n_frames, len(top), 3))
    targets[:, :, 2] = ramp[:, None]
    springs = SpringDrive(top, k_s * share / share.sum(), targets)
    mat = TetMaterials.uniform(len(tets), e_pa, 0.0, 50.0, 1000.0)
    res = simulate(nodes, tets, mat, bottom, np.zeros((n_frames, len(bottom), 3)), 0.01,
                   params=SimulateParams(dt=2e-3), springs=springs)  # fmt: skip
    settled = res.displacements[-1, top, 2]
    np.testing.assert_allclose(settled, k_s * u0 / (k_s + k_block), rtol=1e-3)


def test_landmark_patches_share_the_stiffness_and_stay_on_their_lip() -> None:
    """Two landmarks on a 1 mm grid of skin nodes, the second on the lower lip (y < 0 is the
    lower side): each patch's springs sum to its stiffness, reach 5 mm, never cross the lip
    seam; on a 10 mm grid a patch still pulls 3 nodes, never a single one."""
    g = np.stack(np.meshgrid(np.arange(-10, 11), np.arange(-10, 11)), -1).reshape(-1, 2) * 1e-3
    pts = np.c_[g, np.zeros(len(g))]
    side = np.where(pts[:, 1] < 0, -1, 0)
    landmarks = np.array([[0.0, 0.004, 0.0], [0.0, -0.004, 0.0]])
    motion = np.zeros((2, 2, 3))
    motion[1, 0], motion[1, 1] = 1e-3, 2e-3
    args = (np.array([0, -1]), motion, np.array([100.0, 50.0]), np.array([0.005, 0.005]))
    drive = landmark_drive(np.arange(len(pts)), pts, side, landmarks, *args)
    np.testing.assert_allclose(drive.stiffness.sum(), 150.0)
    near = pts[drive.nodes]
    assert np.linalg.norm(near[:, None] - landmarks[None], axis=2).min(axis=1).max() < 0.005
    lower = side[drive.nodes] == -1
    # lower-lip nodes follow only the lower landmark; y > 0 only the upper one
    np.testing.assert_allclose(drive.targets[1, lower], 2e-3)
    upper_only = near[:, 1] > 0.0
    assert np.all(drive.targets[1, upper_only] <= 1e-3 + 1e-15)
    grid = np.stack(np.meshgrid(np.arange(-2, 3), np.arange(-2, 3)), -1).reshape(-1, 2) * 0.01
    sparse = np.c_[grid, np.zeros(len(grid))]  # 10 mm apart: no node within 5 mm but one
    coarse = landmark_drive(
        np.arange(len(sparse)), sparse, np.zeros(len(sparse)), landmarks[:1], np.array([0]),
        motion[:, :1], np.array([100.0]), np.array([0.005]),
    )  # fmt: skip
    assert len(coarse.nodes) >= MIN_PATCH_NODES
    assert patch_weights(np.array([0.0, 0.005, 0.006]), 0.005).tolist() == [1.0, 0.0, 0.0]


def test_spring_drive_refuses_bad_input() -> None:
    with pytest.raises(ValueError, match="stiffness must be finite"):
        SpringDrive(np.array([0]), np.array([0.0]), np.zeros((2, 1, 3)))
    with pytest.raises(ValueError, match="NaN"):
        SpringDrive(np.array([0]), np.array([1.0]), np.full((2, 1, 3), np.nan))
