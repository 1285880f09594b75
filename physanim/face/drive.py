"""How a tracked face drives its tissue: the boundary conditions of the face FEM.

* Bone side: skull nodes stay fixed in the head frame; mandible nodes turn with the jaw
  (:mod:`physanim.face.jaw`), weighted from 0 at the mouth line to 1 below it.
* Skin: moved by the tissue's fitted active stress (``actuation``: the skin is free here, the
  actuation is the ``actuate`` stage's), tracked landmarks pull small patches by springs
  (``landmarks``, default), the whole skin is pulled towards the kinematic scan
  (``kinematic``), or each landmark's nearest skin node follows it exactly (``prescribed``,
  the seed's setting).

Everything is in the head-fixed scan frame (the marker template's frame), metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from physanim.face.jaw import (
    JawMotion,
    JawPrior,
    estimate_jaw,
    jaw_displacements,
    mandible_weights,
    neighbour_share,
)
from physanim.face.params import DriveParams, JawParams
from physanim.fem.boundary import SpringDrive, landmark_drive, target_drive
from physanim.mesh.seam import UPPER, MouthLine
from physanim.mesh.tetra import boundary_faces, landmark_nodes
from physanim.mesh.topology import vertex_areas


class DriveError(ValueError):
    """The tracked data cannot drive the simulation as configured."""


def head_frame(points: NDArray, poses: NDArray) -> NDArray:
    """Tracked points (T, K, 3) m, camera frame, in the head frame: poses (T, 4, 4) camera <-
    head applied inversely."""
    return np.einsum("tji,tkj->tki", poses[:, :3, :3], points - poses[:, None, :3, 3])


def fill_gaps(trajectories: NDArray) -> tuple[NDArray, NDArray]:
    """Trajectories (T, K, 3) with NaN gaps filled linearly in time (held at the ends), and
    which (K,) were seen in at least one frame (the others stay NaN)."""
    out = np.array(trajectories, dtype=np.float64)
    seen = np.isfinite(out).all(axis=2)
    frames = np.arange(len(out))
    for k in np.nonzero(seen.any(axis=0) & ~seen.all(axis=0))[0]:
        ok = seen[:, k]
        for c in range(3):
            out[:, k, c] = np.interp(frames, frames[ok], out[ok, k, c])
    return out, seen.any(axis=0)


@dataclass(frozen=True)
class FaceDrive:
    """Boundary conditions of the face FEM.

    ``prescribed`` (P,) nodes with ``prescribed_traj`` (T, P, 3) m; ``springs`` (or None);
    ``jaw`` (or None) with ``mandible_weight`` (B,) of the bone-side nodes ``bone`` (B,);
    ``landmarks``: names of the driving landmarks; ``warnings``: what was left out and why.
    """

    prescribed: NDArray
    prescribed_traj: NDArray
    springs: SpringDrive | None
    jaw: JawMotion | None
    bone: NDArray
    mandible_weight: NDArray
    landmarks: list[str]
    warnings: list[str]


def estimate_face_jaw(
    names: list[str],
    rest: NDArray,
    motion: NDArray,
    mouth: MouthLine,
    pronasale: NDArray,
    params: JawParams,
    fallback: NDArray | None = None,
) -> tuple[JawMotion, list[str]]:
    """Jaw motion from the landmarks riding on the mandible.

    ``names`` (K,) with rest positions (K, 3) m and displacements ``motion`` (T, K, 3) m;
    ``fallback`` (T, V, 3) m: positions of other points (the fitted motion mesh) used when
    fewer than 2 landmarks qualify.  Returns the motion and the names used ('fit' for the
    fallback).
    """
    prior = JawPrior(
        pivot=np.asarray(pronasale) + np.asarray(params.pivot_prior_m),
        pivot_std_m=params.pivot_prior_std_m,
        axis_std_rad=np.radians(params.axis_prior_std_deg),
        noise_m=params.noise_m,
        pivot_bound_std=params.pivot_bound_std,
    )
    if params.landmarks is not None:
        unknown = [n for n in params.landmarks if n not in names]
        if unknown:
            raise DriveError(f"simulate.jaw.landmarks: {unknown} were not tracked ({names})")
        use = [names.index(n) for n in params.landmarks]
    else:
        below = mouth.height_at(rest[:, 0]) - rest[:, 1] > params.margin_m
        use = list(np.nonzero(below)[0])
    if len(use) >= 2:
        return estimate_jaw(rest[use][None] + motion[:, use], prior), [names[i] for i in use]
    if fallback is None:
        raise DriveError(
            "no landmark rides on the mandible (more than simulate.jaw.margin_m below the "
            "mouth) and no fitted model to fall back on; set simulate.jaw.landmarks or "
            "simulate.jaw.enabled=false"
        )
    below = mouth.height_at(fallback[0, :, 0]) - fallback[0, :, 1] > params.margin_m
    if below.sum() < 2:
        raise DriveError("the fitted model has no vertices below the mouth: cannot find the jaw")
    return estimate_jaw(fallback[:, below], prior), ["fit"]


def face_drive(
    nodes: NDArray,
    tets: NDArray,
    skin: NDArray,
    bone: NDArray,
    side: NDArray,
    skin_anchor: NDArray,
    mouth: MouthLine,
    jaw: JawMotion | None,
    names: list[str],
    rest: NDArray,
    motion: NDArray,
    params: DriveParams,
    blend_m: float,
    skin_targets: NDArray | None = None,
) -> FaceDrive:
    """Boundary conditions of the face tissue.

    nodes (N, 3) m, tets (M, 4); ``skin``/``bone`` (N,) bool; ``side`` (N,) lip sides;
    ``skin_anchor`` (N, 3) m, the skin point in front of each bone-side node; ``jaw``: the
    mandible's motion, or None to fix every bone-side node; landmarks ``names`` (K,) with
    rest positions (K, 3) m and displacements ``motion`` (T, K, 3) m (NaN: never seen);
    ``skin_targets`` (T, S, 3) m: displacements of the free skin nodes (in node order) for
    the 'kinematic' mode.
    """
    warnings: list[str] = []
    n_t = motion.shape[0]
    bone_idx = np.nonzero(bone)[0]
    if jaw is None:
        weight = np.zeros(len(bone_idx))
        bone_traj = np.zeros((n_t, len(bone_idx), 3))
    else:
        weight = mandible_weights(skin_anchor[bone_idx], mouth, blend_m)
        upper = side[bone_idx] == UPPER
        weight[upper] = 0.0  # the upper lip rides on the skull
        # and its neighbours partly: without this, a tet at the end of the lip seam can join
        # an upper-lip node (0) to nodes of weight ~1, a stress hot spot in that one tet
        weight *= 1.0 - neighbour_share(tets, bone_idx[upper], len(nodes))[bone_idx]
        bone_traj = jaw_displacements(nodes[bone_idx], weight, jaw)
    free_skin = np.nonzero(skin & ~bone)[0]

    chosen = params.landmarks if params.landmarks is not None else names
    unknown = [n for n in chosen if n not in names]
    if unknown:
        raise DriveError(f"simulate.drive.landmarks: {unknown} were not tracked ({names})")
    use = [names.index(n) for n in chosen if n not in params.exclude]
    lost = [names[i] for i in use if not np.isfinite(motion[:, i]).all()]
    if lost and params.mode != "actuation":
        warnings.append(f"landmarks never seen, not driving: {lost}")
    use = [i for i in use if names[i] not in lost]
    driving = [names[i] for i in use]
    springs = None
    prescribed, traj = bone_idx, bone_traj
    if params.mode == "actuation":  # the skin is free: the actuation moves it
        driving = ["actuation"]
    elif params.mode == "kinematic":
        if skin_targets is None:
            raise DriveError("simulate.drive.mode=kinematic needs the kinematic scan targets")
        area = skin_areas(nodes, tets, skin)[free_skin]
        on = area > 0  # skin nodes on no all-skin face (the rim's edge) carry no skin area
        springs = target_drive(
            free_skin[on], params.kinematic_stiffness_N_per_m2 * area[on], skin_targets[:, on]
        )
        driving = ["kinematic scan"]
    elif not use:
        raise DriveError(
            "no landmark drives the skin: check simulate.drive.landmarks / exclude against "
            f"the tracked landmarks {names}"
        )
    elif params.mode == "landmarks":
        stiffness = np.array(
            [params.stiffness_overrides_N_per_m.get(names[i], params.stiffness_N_per_m)
             for i in use]
        )  # fmt: skip
        springs = landmark_drive(
            free_skin, nodes[free_skin], side[free_skin], rest[use], mouth.side(rest[use]),
            motion[:, use], stiffness, np.full(len(use), params.radius_m),
        )  # fmt: skip
    else:  # prescribed: the nearest free skin node follows each landmark exactly
        mask = skin & ~bone
        node, _ = landmark_nodes(nodes, mask, side, rest[use], mouth.side(rest[use]))
        node, first = np.unique(node, return_index=True)
        if len(first) < len(use):
            warnings.append("landmarks sharing a skin node: the first one drives it")
        prescribed = np.r_[bone_idx, node]
        traj = np.concatenate([bone_traj, motion[:, np.asarray(use)[first]]], axis=1)
        driving = [driving[i] for i in first]
    return FaceDrive(prescribed, traj, springs, jaw, bone_idx, weight, driving, warnings)


def skin_areas(nodes: NDArray, tets: NDArray, skin: NDArray) -> NDArray:
    """Skin area (N,) m^2 of each node: a third of each incident boundary face whose nodes
    are all skin nodes (0 off the skin and at its rim's edge); nodes (N, 3) m, tets (M, 4),
    skin (N,) bool."""
    outer = boundary_faces(tets)
    return vertex_areas(nodes, outer[skin[outer].all(axis=1)])
