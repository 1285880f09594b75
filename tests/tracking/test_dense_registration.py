"""The dense stage's scan registration: a registration out of reach is not applied and the
stage's summary says so; an applied one reports how far it moved the tracker's pose."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.tracking.register import Registration, register_to_depth
from tasks.dense import _registration_summary

K = np.array([[500.0, 0.0, 160.0], [0.0, 500.0, 120.0], [0.0, 0.0, 1.0]])


def test_a_registration_out_of_reach_is_not_applied_and_says_so() -> None:
    """A 4 x 4 cm patch facing the camera, posed 10 cm beside the wall it should lie on, finds
    no depth within reach."""
    g = np.linspace(-0.02, 0.02, 9)
    points = np.stack([*np.meshgrid(g, g), np.zeros((9, 9))], axis=-1).reshape(-1, 3)
    normals = np.tile([0.0, 0.0, -1.0], (len(points), 1))  # towards the camera
    depth = np.full((240, 320), np.nan, np.float32)
    depth[:, :160] = 0.5  # a wall in the left half of the image only
    pose = np.eye(4)
    pose[:3, 3] = [-0.05, 0.0, 0.5]  # on the wall
    found = register_to_depth(points, normals, depth, K, pose, 0.02, 0.004)
    assert found.converged and np.allclose(found.pose[:3, 3], pose[:3, 3], atol=1e-6)
    far = pose.copy()
    far[:3, 3] += [0.1, 0.0, 0.0]  # beside the wall: nothing measured under the patch
    lost = register_to_depth(points, normals, depth, K, far, 0.02, 0.004)
    assert not lost.converged
    summary = _registration_summary(lost, far)
    assert "did not register" in summary["warnings"][0]


def test_the_summary_gives_the_shift_and_turn_of_the_tracker_pose() -> None:
    tracker = np.eye(4)
    tracker[:3, 3] = [0.1, 0.0, 0.5]
    registered = np.eye(4)
    c, s = np.cos(np.radians(3.0)), np.sin(np.radians(3.0))
    registered[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    registered[:3, 3] = [0.1, 0.004, 0.497]
    figures = _registration_summary(Registration(registered, 900, 1000, 3e-4), tracker)
    assert "warnings" not in figures
    assert figures["registration_shift_mm"] == pytest.approx(5.0, abs=1e-3)
    assert figures["registration_turn_deg"] == pytest.approx(3.0, abs=1e-3)
    assert figures["registration_rms_mm"] == pytest.approx(0.3)
