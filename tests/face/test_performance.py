"""The simulate stage's summary says when a node outruns everything that drives the tissue."""

from __future__ import annotations

import numpy as np

from physanim.face.drive import FaceDrive
from physanim.face.performance import runaway_warning
from physanim.fem.boundary import SpringDrive


def _drive(reach_m: float) -> FaceDrive:
    traj = np.zeros((3, 2, 3))
    traj[2, 0, 1] = reach_m  # a prescribed node moves by reach_m
    springs = SpringDrive(np.array([5]), np.array([10.0]), np.zeros((3, 1, 3)))
    return FaceDrive(np.array([0, 1]), traj, springs, None, np.array([0, 1]), np.ones(2), [], [])


def test_a_node_outrunning_the_drive_is_named() -> None:
    """A free node three times farther than the drive's largest motion (0.01 m) is a mesh
    mechanism or a blow-up (a hinged tet drifted by 0.8 m on a demo mesh): named, with the
    fix; twice as far (a bulge the drive can make) is not."""
    drive = _drive(0.01)
    d = np.zeros((3, 8, 3))
    d[2, 7, 2] = 0.02
    assert runaway_warning(d, drive) is None
    d[2, 7, 2] = 0.05
    warning = runaway_warning(d, drive)
    assert warning is not None and warning.startswith("node 7 moved 50.0 mm, 5 times")
    assert "physanim run --force tetra" in warning
