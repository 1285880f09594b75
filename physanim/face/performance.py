"""The face FEM's boundary conditions from a tracked performance (which drive, which jaw).

Chooses what ``physanim.fem.simulate`` is driven by: the tracked landmarks in the head
frame (gaps filled, displacements from the first frame), the mandible turned by the jaw
rotation estimated from them (``JawParams.enabled``), and the skin pulled by landmark springs,
by the kinematic scan (``DriveParams.mode == "kinematic"``) or prescribed at single nodes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from physanim.face.drive import (
    FaceDrive,
    estimate_face_jaw,
    face_drive,
    fill_gaps,
    head_frame,
    kinematic_targets,
)
from physanim.face.params import DriveParams, JawParams
from physanim.mesh.seam import MouthLine, bind_across_seam


def landmark_motion(points: NDArray, head_pose: NDArray) -> NDArray:
    """Tracked landmarks (T, K, 3) m in the camera frame -> displacements (T, K, 3) m from the
    first frame in the head frame (head pose (T, 4, 4) removed, gaps filled)."""
    trajectories, _ = fill_gaps(head_frame(points, head_pose))
    return trajectories - trajectories[:1]


def performance_drive(
    landmark_names: list[str],
    rest: NDArray,
    motion: NDArray,
    mouth: MouthLine,
    pronasale: NDArray,
    motion_mesh: NDArray,
    tissue: dict[str, NDArray],
    scan: tuple[NDArray, NDArray],
    scan_motion: Callable[[], NDArray],
    drive: DriveParams,
    jaw: JawParams,
) -> FaceDrive:
    """Boundary conditions of the face tissue for one performance.

    ``landmark_names`` (K) with neutral positions ``rest`` (K, 3) m and displacements
    ``motion`` (T, K, 3) m (``landmark_motion``); ``mouth`` the lip seam; ``pronasale`` (3,)
    m; ``motion_mesh`` (T, V, 3) m the fitted mesh in the scan frame (the jaw's fallback);
    ``tissue``: ``nodes`` (N, 3) m, ``tets`` (M, 4), ``skin``/``bone`` (N,) bool, ``side``
    (N,), ``skin_anchor`` (N, 3) m; ``scan`` (vertices (S, 3) m, faces); ``scan_motion()``
    the kinematic scan (T, S, 3) m, called only for the kinematic drive.
    """
    nodes, tets, skin, bone, side = (tissue[k] for k in ("nodes", "tets", "skin", "bone", "side"))
    jaw_motion = None
    if jaw.enabled:
        jaw_motion, _ = estimate_face_jaw(
            landmark_names, rest, motion, mouth, pronasale, jaw, motion_mesh
        )
    targets = None
    if drive.mode == "kinematic":
        free = np.nonzero(skin & ~bone)[0]
        binding = bind_across_seam(nodes[free], side[free], scan[0], scan[1], mouth)
        targets = kinematic_targets(binding, scan[1], np.asarray(scan_motion(), np.float64))
    return face_drive(
        nodes, tets, skin, bone, side, tissue["skin_anchor"], mouth, jaw_motion,
        landmark_names, rest, motion, drive, jaw.blend_m, targets,
    )  # fmt: skip
