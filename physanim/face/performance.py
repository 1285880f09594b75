"""The face FEM's boundary conditions from a tracked performance (which drive, which jaw).

Chooses what ``physanim.fem.simulate`` is driven by: the tracked landmarks in the head
frame (gaps filled, displacements from the first frame), the mandible turned by the jaw
rotation estimated from them (``JawParams.enabled``), and the skin pulled by landmark springs,
by the kinematic scan (``DriveParams.mode == "kinematic"``) or prescribed at single nodes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from physanim.face.drive import FaceDrive, estimate_face_jaw, face_drive, fill_gaps, head_frame
from physanim.face.params import DriveParams, JawParams
from physanim.fem.params import SimulateParams
from physanim.mesh.kinematic import blend_frames, blend_matrix
from physanim.mesh.seam import MouthLine, bind_across_seam


def landmark_motion(points: NDArray, head_pose: NDArray) -> NDArray:
    """Tracked landmarks (T, K, 3) m in the camera frame -> displacements (T, K, 3) m from the
    first frame in the head frame (head pose (T, 4, 4) removed, gaps filled)."""
    trajectories, _ = fill_gaps(head_frame(points, head_pose))
    return trajectories - trajectories[:1]


@dataclass(frozen=True)
class SkinBinding:
    """The free skin nodes ``nodes`` (S,) of a tissue mesh (skin, not bone side) bound to a
    scan: ``blend`` (S, V) barycentric weights of the scan's V vertices at each node's
    closest point (never across the lip seam). Carries per-vertex captured motion to them."""

    nodes: NDArray
    blend: sp.csr_array

    @classmethod
    def of(
        cls, tissue: dict[str, NDArray], mouth: MouthLine, scan: tuple[NDArray, NDArray]
    ) -> SkinBinding:
        """The binding of ``tissue``'s (``nodes``, ``skin``, ``bone``, ``side``) free skin
        nodes to ``scan`` (vertices (V, 3) m, faces (F, 3)) cut along ``mouth``."""
        nodes, skin, bone, side = (tissue[k] for k in ("nodes", "skin", "bone", "side"))
        free = np.nonzero(skin & ~bone)[0]
        binding = bind_across_seam(nodes[free], side[free], scan[0], scan[1], mouth)
        return cls(free, blend_matrix(binding, scan[1], len(scan[0])))

    def displacements(self, scan_motion: NDArray) -> NDArray:
        """Displacements (T, S, 3) m from frame 0 of the nodes when the scan's vertices move
        by ``scan_motion`` (T, V, 3) m (positions, or displacements from any rest)."""
        used = np.unique(self.blend.indices)  # only the vertices the nodes are bound to
        moved = np.asarray(scan_motion[:, used], dtype=np.float64)
        return blend_frames(self.blend[:, used], moved - moved[:1])

    def values(self, per_vertex: NDArray) -> NDArray:
        """Per-frame scalars (T, V) of the scan's vertices (a confidence) at the nodes (T, S)."""
        return (self.blend @ np.asarray(per_vertex, dtype=np.float64).T).T


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
        targets = SkinBinding.of(tissue, mouth, scan).displacements(scan_motion())
    return face_drive(
        nodes, tets, skin, bone, side, tissue["skin_anchor"], mouth, jaw_motion,
        landmark_names, rest, motion, drive, jaw.blend_m, targets,
    )  # fmt: skip


def performance_summary(
    result: Any, drive: FaceDrive, n_skin: int, params: SimulateParams, mode: str
) -> dict[str, Any]:
    """The simulate stage's summary of a ``physanim.fem.simulate`` result (mm, kPa, s):
    stepping, solver, drive (``mode``, landmarks, share of the ``n_skin`` skin nodes held by
    springs), peak displacement and stress, inverted tets, timings, the jaw, warnings."""
    from physanim.fem.linsolve import blas_in_use
    from physanim.fem.simulate import frames_per_thread_count, hot_spot_ratio

    springs = drive.springs
    summary: dict[str, Any] = {
        "frames": len(result.displacements),
        "dt_s": result.dt,
        "substeps_per_frame": result.n_substeps,
        "stepping": params.stepping,
        "steps": int(result.frame_substeps.sum()),
        "check_steps": result.check_steps,
        "frames_over_tolerance": result.frames_over_tolerance,
        "blas": blas_in_use(),
        "solver_threads": frames_per_thread_count(result.solver_threads),
        "drive": mode,
        "driving_landmarks": len(drive.landmarks),
        "spring_node_fraction_of_skin": round(len(springs.nodes) / n_skin, 4) if springs else 0,
        "max_displacement_mm": round(float(np.abs(result.displacements).max()) * 1e3, 3),
        "peak_von_mises_kPa": round(float(result.max_von_mises.max()) / 1e3, 3),
        "peak_to_p99_von_mises": round(hot_spot_ratio(result), 3),
        "inverted_tets": int(len(result.inverted_tets)),
        "seconds": {k: round(v, 3) for k, v in result.timings.items()},
    }
    if result.solver:  # a full run (a reduced preview has no factor of its own)
        summary.update(solver=result.solver, factor_entries=result.factor_entries)
    if drive.jaw is not None:
        summary["jaw_max_angle_deg"] = round(float(np.degrees(drive.jaw.angle.max())), 3)
        summary["jaw_pivot_mm"] = [round(float(x) * 1e3, 2) for x in drive.jaw.pivot]
    warnings = list(drive.warnings)
    runaway = runaway_warning(result.displacements, drive)
    if runaway:
        warnings.append(runaway)
    if warnings:
        summary["warnings"] = warnings
    return summary


#: A free node moving this many times farther than anything the drive moves is a fault.
RUNAWAY_FACTOR = 3.0


def runaway_warning(displacements: NDArray, drive: FaceDrive) -> str | None:
    """A warning when a node of the simulation (T, N, 3) m moved more than
    ``RUNAWAY_FACTOR`` times the drive's largest motion (prescribed nodes, spring targets):
    tissue pulled by the skin and the jaw cannot outrun them, so such a node is a mesh
    mechanism or a blow-up, not physics; None otherwise."""
    driven = [np.abs(drive.prescribed_traj).max(initial=0.0)]
    if drive.springs is not None:
        driven.append(np.abs(drive.springs.targets).max(initial=0.0))
    reach = max(driven)
    moved = np.linalg.norm(displacements, axis=-1).max(axis=0)
    node = int(moved.argmax())
    if reach <= 0 or moved[node] <= RUNAWAY_FACTOR * reach:
        return None
    return (
        f"node {node} moved {moved[node] * 1e3:.1f} mm, {moved[node] / reach:.0f} times the "
        f"drive's largest motion ({reach * 1e3:.1f} mm): a mechanism in the tissue mesh or "
        "an unstable step, not physics; remesh (physanim run --force tetra) or lower simulate.dt"
    )
