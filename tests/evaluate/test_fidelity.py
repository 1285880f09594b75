"""Motion fidelity against a true surface: 0 for the truth, 1 for a face that does not move."""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from physanim.evaluate.fidelity import (
    REGIONS,
    face_regions,
    follow_truth,
    lip_gap,
    motion_fidelity,
    relative_error,
)


def moving_sheet(n_frames: int = 6):
    """A flat sheet whose lower half drops and turns: (T, V, 3) m, faces."""
    g = np.stack(np.meshgrid(np.linspace(-0.05, 0.05, 41), np.linspace(-0.05, 0.05, 41)), -1)
    v0 = np.c_[g.reshape(-1, 2), np.zeros(g.size // 2)]
    f = Delaunay(v0[:, :2]).simplices
    t = np.linspace(0, 1, n_frames)[:, None, None]
    low = (v0[:, 1] < 0)[None, :, None]
    drop = np.array([0.0, -0.01, 0.003]) + 0.1 * v0 * np.array([0, 0, 1])
    return v0[None] + t * low * drop, f


LANDMARKS = {
    "ch_L": np.array([0.02, -0.01, 0]), "ch_R": np.array([-0.02, -0.01, 0]),
    "pronasale": np.array([0.0, 0.01, 0]), "glabella": np.array([0.0, 0.04, 0]),
    "al_L": np.array([0.012, 0.01, 0]), "al_R": np.array([-0.012, 0.01, 0]),
}  # fmt: skip


def test_fidelity_is_zero_for_the_truth_and_one_for_a_still_face() -> None:
    tv, tf = moving_sheet()
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.045, 0.045, (500, 3)) * np.array([1, 1, 0])
    tm = follow_truth(pts, tv, tf)
    labels = face_regions(pts, LANDMARKS)
    exact = motion_fidelity(tm.displacement, tm.displacement, labels)
    still = motion_fidelity(np.zeros_like(tm.displacement), tm.displacement, labels)
    assert np.isnan(exact.overall[0])  # nothing moves at frame 0
    np.testing.assert_allclose(exact.overall[1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(still.overall[1:], 1.0)
    half = 0.5 * tm.displacement
    np.testing.assert_allclose(relative_error(half, tm.displacement)[1:], 0.5)
    moving = REGIONS.index("jaw_chin")
    np.testing.assert_allclose(still.regions[1:, moving], 1.0)
    assert np.isnan(still.regions[-1, REGIONS.index("forehead")])  # the forehead stays put


def test_regions_and_lip_gap() -> None:
    pts = np.array([[0.0, -0.012, 0], [0.0, -0.03, 0], [0.04, 0.0, 0], [0.0, 0.015, 0],
                    [0.0, 0.05, 0]])  # fmt: skip
    names = [REGIONS[i] for i in face_regions(pts, LANDMARKS)]
    assert names == ["mouth", "jaw_chin", "cheeks", "nose", "forehead"]
    up, low = np.zeros((3, 3)), np.array([[0, -0.006, 0], [0, -0.01, 0], [0, -0.002, 0.0]])
    np.testing.assert_allclose(lip_gap(up, low), [0.006, 0.01, 0.002])


def test_points_in_a_hole_of_the_truth_have_no_truth() -> None:
    """A model surface that fills a hole of the true surface: its points in the hole are as
    far from the truth as from the hole's rim, and the rim's motion is not theirs."""
    tv, tf = moving_sheet()
    inside = np.abs(tv[0][:, :2] - [0.0, -0.02]).max(axis=1) < 0.005 + 1e-9
    tf = tf[~inside[tf].all(axis=1)]  # a 10 mm square hole on the sheet's 2.5 mm grid
    g = np.stack(np.meshgrid(np.linspace(-0.04, 0.04, 81), np.linspace(-0.04, 0.04, 81)), -1)
    pts = np.c_[g.reshape(-1, 2), np.zeros(g.size // 2)]  # every 1 mm, over the hole too
    tm = follow_truth(pts, tv, tf)
    depth_in_hole = 0.005 - np.abs(pts[:, :2] - [0.0, -0.02]).max(axis=1)  # from its rim, m
    np.testing.assert_allclose(tm.distance, np.maximum(depth_in_hole, 0.0), atol=1e-7)
    on = tm.on_truth()  # within 1 mm of the true surface
    assert on[depth_in_hole < 0.0009].all() and not on[depth_in_hole > 0.0011].any()
    assert 49 <= (~on).sum() <= 81  # 7 x 7 points more than 1 mm inside the rim, 9 x 9 at 1 mm
    # a model that moves the points in the hole wrongly is as good as the truth where it has one
    model = tm.displacement.copy()
    model[:, ~on] += [0.0, 0.0, 0.005]
    assert relative_error(model, tm.displacement)[-1] > 0.05
    np.testing.assert_allclose(
        relative_error(model[:, on], tm.displacement[:, on])[1:], 0.0, atol=1e-12
    )
