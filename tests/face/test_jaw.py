"""Jaw hinge estimation and the mandible's boundary motion."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.face.jaw import (
    JawEstimateError,
    JawMotion,
    JawPrior,
    estimate_jaw,
    jaw_displacements,
    mandible_weights,
    neighbour_share,
)
from physanim.mesh.seam import straight_mouth_line

#: chin points of the demo actor (m, actor frame) and its true jaw hinge
CHIN = np.array([[0.006, -0.033, -0.036], [0.016, -0.030, -0.038], [-0.018, -0.028, -0.030]])
PIVOT = np.array([0.0, 0.005, -0.085])


def _turned(points, pivot, axis, angle):
    return (
        JawMotion(pivot, axis, angle, np.zeros(len(angle))).rotations() @ (points - pivot).T
        + pivot[:, None]
    )


def test_jaw_rotation_recovered_from_noisy_landmarks_to_half_a_degree() -> None:
    """A tilted hinge 1 cm away from the prior's pivot, 0.1 mm tracking noise: the angle of
    every frame within 0.5 deg, the pivot within 2 mm."""
    rng = np.random.default_rng(3)
    axis = np.array([1.0, 0.06, -0.03]) / np.linalg.norm([1.0, 0.06, -0.03])
    angle = 0.2 * np.sin(np.linspace(0.0, np.pi, 40)) ** 2
    moved = np.stack([_turned(CHIN, PIVOT, axis, angle[[t]])[0].T for t in range(40)])
    moved[1:] += rng.normal(0.0, 1e-4, moved[1:].shape)
    prior = JawPrior(pivot=PIVOT + np.array([0.0, 0.007, 0.007]))
    jaw = estimate_jaw(moved, prior)
    assert np.degrees(np.abs(jaw.angle - angle).max()) < 0.5
    assert np.linalg.norm(jaw.pivot[1:] - PIVOT[1:]) < 2e-3
    assert np.degrees(np.arccos(abs(jaw.axis @ axis))) < 3.0
    assert jaw.residual_m.max() < 5e-4


def test_the_pivot_stays_within_its_bound_when_the_chin_moves_without_the_jaw() -> None:
    """Chin points pushed 3 mm forward with no turn at all (the skin of a lip press): left
    free, the fit explains it as a turn about a pivot 50 mm in front of the TMJ; bounded to
    3 standard deviations (30 mm) per coordinate, the pivot stays there and the turn it reads
    is smaller."""
    rng = np.random.default_rng(4)
    ramp = np.sin(np.linspace(0.0, np.pi, 30)) ** 2
    moved = CHIN[None] + ramp[:, None, None] * np.array([0.0, 0.0, 0.003])
    moved[1:] += rng.normal(0.0, 1e-4, moved[1:].shape)
    free = estimate_jaw(moved, JawPrior(pivot=PIVOT, pivot_bound_std=100.0))
    bounded = estimate_jaw(moved, JawPrior(pivot=PIVOT))
    assert np.abs(free.pivot - PIVOT).max() > 0.04
    assert np.abs(bounded.pivot - PIVOT).max() <= 0.03 + 1e-9
    assert np.abs(bounded.angle).max() < 0.8 * np.abs(free.angle).max()


def test_jaw_estimate_refuses_unusable_points() -> None:
    with pytest.raises(JawEstimateError, match="K >= 2"):
        estimate_jaw(np.zeros((5, 1, 3)), JawPrior(pivot=PIVOT))
    bad = np.zeros((5, 3, 3))
    bad[0, 1] = np.nan
    with pytest.raises(JawEstimateError, match="frame 0"):
        estimate_jaw(bad, JawPrior(pivot=PIVOT))


def test_mandible_weights_and_displacements() -> None:
    mouth = straight_mouth_line(np.array([-0.02, -0.018, 0.0]), np.array([0.02, -0.018, 0.0]))
    y = np.array([-0.010, -0.018, -0.022, -0.026, -0.040])
    pts = np.c_[np.zeros(5), y, np.full(5, -0.03)]
    w = mandible_weights(pts, mouth, 0.008)
    np.testing.assert_allclose(w, [0.0, 0.0, 0.5, 1.0, 1.0])
    jaw = JawMotion(PIVOT, np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.2]), np.zeros(2))
    d = jaw_displacements(pts, w, jaw)
    assert np.all(d[0] == 0.0)  # reference frame: exactly at rest
    exact = _turned(pts, PIVOT, jaw.axis, np.array([0.2]))[0].T - pts
    np.testing.assert_allclose(d[1], w[:, None] * exact, atol=1e-15)
    assert d[1, -1, 1] < -5e-3  # the chin moves down when the jaw opens


def test_neighbour_share_is_the_mean_member_fraction_of_a_nodes_tets():
    """Two tets sharing face (1, 2, 3), node 0 a member: tet shares 1/4 and 0, so node 0 gets
    1/4, the shared nodes (1/4 + 0) / 2 and node 4 (only in the second tet) 0."""
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    share = neighbour_share(tets, np.array([0]), 6)
    np.testing.assert_allclose(share, [0.25, 0.125, 0.125, 0.125, 0.0, 0.0])
