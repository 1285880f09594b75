"""Soft drives of the FEM skin: springs that pull nodes towards moving targets.

A :class:`SpringDrive` adds, for each listed node i, the energy ``k_i / 2 |d_i - u_i(t)|^2``:
a constant diagonal stiffness (so the Newmark matrix is still factorised once) and a
force ``k_i u_i(t)``.  The tissue's own stiffness competes with the pull, so an edited
material moves differently from the capture.

* :func:`landmark_drive`: each tracked landmark pulls a small skin patch around it (weights
  falling smoothly from 1 at the landmark to 0 at ``radius``) towards the landmark's tracked
  displacement, with a total stiffness per landmark.
* :func:`target_drive`: every listed node pulled towards its own target (e.g. the kinematic
  scan), the way secondary motion is layered on animation in production rigs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from physanim.fem.geometry import node_dofs
from physanim.mesh.seam import NONE


@dataclass(frozen=True)
class SpringDrive:
    """Springs on ``nodes`` (S,) with ``stiffness`` (S,) N/m towards ``targets`` (T, S, 3) m
    (displacements from rest at the frame times)."""

    nodes: NDArray
    stiffness: NDArray
    targets: NDArray

    def __post_init__(self) -> None:
        s = len(self.nodes)
        if (
            self.stiffness.shape != (s,)
            or self.targets.ndim != 3
            or self.targets.shape[1:]
            != (
                s,
                3,
            )
        ):
            raise ValueError(
                f"spring drive: nodes ({s},), stiffness {self.stiffness.shape} and targets "
                f"{self.targets.shape} must be (S,), (S,) and (T, S, 3)"
            )
        if np.unique(self.nodes).size != s:
            raise ValueError("spring drive: repeated nodes")
        if np.any(self.stiffness <= 0) or not np.all(np.isfinite(self.stiffness)):
            raise ValueError("spring drive: stiffness must be finite and > 0 N/m")
        if not np.all(np.isfinite(self.targets)):
            raise ValueError("spring drive: targets contain NaN or Inf")

    def dofs(self) -> NDArray:
        """DOF indices (3S,) of the driven nodes, interleaved x, y, z."""
        return node_dofs(self.nodes)

    def matrix(self, n_dofs: int) -> sp.csr_matrix:
        """(n_dofs, n_dofs) diagonal spring stiffness, N/m."""
        diag = np.zeros(n_dofs)
        diag[self.dofs()] = np.repeat(self.stiffness, 3)
        return sp.diags(diag, format="csr")


#: A landmark's patch always reaches at least this many nodes (see :func:`landmark_drive`).
MIN_PATCH_NODES = 3


def patch_weights(distance: NDArray, radius: NDArray) -> NDArray:
    """Smooth falloff (1 - (d/r)^2)^2 for d < r, else 0 (C1 at the rim); broadcasts."""
    s = np.clip(np.asarray(distance) / np.asarray(radius), 0.0, 1.0)
    return (1.0 - s * s) ** 2


def landmark_drive(
    node_ids: NDArray,
    node_points: NDArray,
    node_side: NDArray,
    landmark_points: NDArray,
    landmark_side: NDArray,
    landmark_displacements: NDArray,
    stiffness: NDArray,
    radius_m: NDArray,
) -> SpringDrive:
    """Springs of L landmark patches over candidate skin nodes.

    node_ids (N,) node indices with rest positions ``node_points`` (N, 3) m and lip sides
    ``node_side`` (N,) (a patch never crosses the lip seam); ``landmark_points`` (L, 3) m at
    rest with sides (L,), ``landmark_displacements`` (T, L, 3) m; ``stiffness`` (L,) N/m,
    the total spring stiffness of each patch; ``radius_m`` (L,) patch radius, m.  A node in
    several patches gets the sum of their springs and the stiffness-weighted mean target.
    Where the mesh is coarse, a patch widens to 1.5 times the distance of its
    MIN_PATCH_NODES-th nearest node, so it never pulls a single node.
    """
    p = np.asarray(node_points, dtype=np.float64)
    lm = np.asarray(landmark_points, dtype=np.float64)
    dist = np.linalg.norm(p[None] - lm[:, None], axis=2)  # (L, N)
    compatible = (np.asarray(landmark_side)[:, None] == NONE) | (
        np.asarray(node_side)[None] == NONE
    )
    compatible |= np.asarray(landmark_side)[:, None] == np.asarray(node_side)[None]
    dist = np.where(compatible, dist, np.inf)
    # on a coarse mesh a patch grows to reach its MIN_PATCH_NODES nearest nodes: a single
    # pulled node is a point load, a stress hot spot
    k = min(MIN_PATCH_NODES, dist.shape[1]) - 1
    reach = 1.5 * np.partition(dist, k, axis=1)[:, k]
    radius = np.maximum(
        np.asarray(radius_m, dtype=np.float64), np.where(np.isfinite(reach), reach, 0)
    )
    w = patch_weights(dist, radius[:, None])
    nearest = np.argmin(dist, axis=1)
    w[np.arange(len(lm)), nearest] = np.maximum(w[np.arange(len(lm)), nearest], 1e-3)
    w /= w.sum(axis=1, keepdims=True)
    k_ln = np.asarray(stiffness, dtype=np.float64)[:, None] * w  # (L, N) N/m
    used = np.nonzero(k_ln.sum(axis=0) > 0)[0]
    k = k_ln[:, used].sum(axis=0)
    targets = np.einsum("ln,tlc->tnc", k_ln[:, used], np.asarray(landmark_displacements))
    targets /= k[None, :, None]
    return SpringDrive(np.asarray(node_ids)[used], k, targets)


def target_drive(node_ids: NDArray, stiffness: NDArray, targets: NDArray) -> SpringDrive:
    """Every node of ``node_ids`` (N,) pulled to its own target (T, N, 3) m, stiffness (N,)."""
    return SpringDrive(np.asarray(node_ids), np.asarray(stiffness, float), np.asarray(targets))
