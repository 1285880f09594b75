"""Boundary conditions of the FEM: driven and fixed nodes (:class:`BoundaryConditions`) and
soft drives of the skin, springs that pull nodes towards moving targets.

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
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from physanim.fem.geometry import node_dofs
from physanim.fem.interp import catmull_rom, catmull_rom_position, tangents
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


def _node_index(name: str, idx: NDArray | None, n_nodes: int) -> NDArray:
    idx = np.zeros(0, np.int64) if idx is None else np.asarray(idx, dtype=np.int64).ravel()
    if idx.size and (idx.min() < 0 or idx.max() >= n_nodes):
        raise ValueError(
            f"{name} must index nodes in [0, {n_nodes}), got [{idx.min()}, {idx.max()}]"
        )
    if np.unique(idx).size != idx.size:
        raise ValueError(f"{name} contains repeated node indices")
    return idx


@dataclass(frozen=True)
class FrameForce:
    """Nodal forces given at the capture frames on some DOFs, N, interpolated between frames
    like the prescribed motion (Catmull-Rom): spring pulls k_i u_i(t), active forces.

    ``values`` (T, K) N on ``dofs`` (K,), which sit at ``positions`` (K,) among the
    ``n_free`` free DOFs; frames ``frame_dt`` s apart."""

    values: NDArray
    dofs: NDArray
    positions: NDArray
    frame_dt: float
    n_free: int

    @cached_property
    def _tangents(self) -> NDArray:
        """Catmull-Rom tangents (T, K) of the frame forces, N/s."""
        return tangents(self.values, self.frame_dt)

    def at(self, times: NDArray) -> NDArray:
        """(len(times), K) forces on ``dofs``, N."""
        return catmull_rom_position(self.values, self.frame_dt, times, self._tangents)

    def free(self, times: NDArray) -> NDArray:
        """(len(times), n_free) forces on the free DOFs, N."""
        out = np.zeros((len(times), self.n_free))
        out[:, self.positions] = self.at(times)
        return out

    def full(self, time: float, n_dofs: int) -> NDArray:
        """(n_dofs,) forces at one time, N."""
        out = np.zeros(n_dofs)
        out[self.dofs] = self.at(np.array([time]))[0]
        return out

    def __add__(self, other: FrameForce) -> FrameForce:
        """Both forces on the union of their DOFs (same frames and free DOFs)."""
        if (other.frame_dt, other.n_free, len(other.values)) != (
            self.frame_dt,
            self.n_free,
            len(self.values),
        ):
            raise ValueError("forces to add must share frame times and free DOFs")
        dofs, at = np.unique(np.r_[self.dofs, other.dofs], return_inverse=True)
        values = np.zeros((len(self.values), len(dofs)))
        values[:, at[: len(self.dofs)]] += self.values  # each force's DOFs are distinct
        values[:, at[len(self.dofs) :]] += other.values
        positions = np.zeros(len(dofs), dtype=np.int64)
        positions[at] = np.r_[self.positions, other.positions]
        return FrameForce(values, dofs, positions, self.frame_dt, self.n_free)


@dataclass(frozen=True)
class BoundaryConditions:
    """Driven nodes ``driven_idx`` (n_d,) following ``values`` (T, 3 n_d) m (displacements
    from rest at frame times k ``frame_dt`` s, Catmull-Rom between frames), nodes
    ``fixed_idx`` (n_f,) held at rest, optional ``springs`` on free nodes (same frame times).
    Build with :meth:`checked`."""

    driven_idx: NDArray
    fixed_idx: NDArray
    values: NDArray
    frame_dt: float
    springs: SpringDrive | None = None

    @classmethod
    def checked(
        cls,
        n_nodes: int,
        driven_idx: NDArray,
        driven_traj: NDArray,
        frame_dt: float,
        fixed_idx: NDArray | None = None,
        springs: SpringDrive | None = None,
    ) -> BoundaryConditions:
        """Validated conditions on a mesh of ``n_nodes``; driven_traj (T >= 2, n_d, 3) m.
        Raises ValueError naming the argument and the rule."""
        driven_idx = _node_index("driven_idx", driven_idx, n_nodes)
        fixed_idx = _node_index("fixed_idx", fixed_idx, n_nodes)
        traj = np.asarray(driven_traj, dtype=np.float64)
        if traj.ndim != 3 or traj.shape[1:] != (driven_idx.size, 3) or len(traj) < 2:
            raise ValueError(
                f"driven_traj must have shape (T >= 2, {driven_idx.size}, 3), got {traj.shape}"
            )
        if not np.isfinite(traj).all():
            raise ValueError("driven_traj contains NaN or Inf")
        if np.intersect1d(driven_idx, fixed_idx).size:
            raise ValueError("driven_idx and fixed_idx share nodes; a node is driven or fixed")
        if not frame_dt > 0:
            raise ValueError(f"frame_dt must be > 0 s, got {frame_dt}")
        if springs is not None:
            if len(springs.targets) != len(traj):
                raise ValueError(
                    f"springs have {len(springs.targets)} frames of targets, "
                    f"driven_traj {len(traj)}"
                )
            if np.intersect1d(springs.nodes, np.r_[driven_idx, fixed_idx]).size:
                raise ValueError("spring nodes must be free: not in driven_idx or fixed_idx")
        return cls(driven_idx, fixed_idx, traj.reshape(len(traj), -1), frame_dt, springs)

    @property
    def n_frames(self) -> int:
        return len(self.values)

    @property
    def prescribed_dofs(self) -> NDArray:
        """(n_c,) prescribed DOFs: the driven nodes' then the fixed nodes'."""
        return np.concatenate([node_dofs(self.driven_idx), node_dofs(self.fixed_idx)])

    @cached_property
    def _tangents(self) -> NDArray:
        return tangents(self.values, self.frame_dt)

    def prescribed(self, times: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """Displacement, velocity, acceleration (len(times), n_c) of the prescribed DOFs."""
        d, v, a = catmull_rom(self.values, self.frame_dt, times, self._tangents)
        pad = np.zeros((len(times), 3 * self.fixed_idx.size))
        return tuple(np.hstack([x, pad]) for x in (d, v, a))

    def drive_defect(self, start: float, h: float, n_sub: int) -> NDArray:
        """Summed local error, m, (n_c,) of ``n_sub`` Newmark steps of ``h`` s from ``start`` s
        in following the prescribed path of each prescribed DOF: each step's trapezoidal defect
        d(t + h) - d(t) - h v(t) - h^2/4 (a(t) + a(t + h)) (= -h^3/12 times the third
        derivative on a Catmull-Rom segment; 0 for fixed DOFs)."""
        times = start + h * np.arange(n_sub + 1)
        d, v, a = self.prescribed(times)
        return (d[1:] - d[:-1] - h * v[:-1] - 0.25 * h * h * (a[:-1] + a[1:])).sum(axis=0)

    def with_springs(
        self,
        K: sp.csr_matrix | None,
        split: tuple[sp.csr_matrix, sp.csr_matrix, NDArray] | None,
    ) -> tuple[sp.csr_matrix | None, tuple[sp.csr_matrix, sp.csr_matrix, NDArray] | None]:
        """Stiffness K (n, n) N/m and its optional split (K_el, G, w) plus the springs'
        (K may be None when the split is given: it stays None)."""
        if self.springs is None:
            return K, split
        n = (K if K is not None else split[0]).shape[0]
        k_springs = self.springs.matrix(n)
        if split is not None:
            split = ((split[0] + k_springs).tocsr(), split[1], split[2])
        return None if K is None else (K + k_springs).tocsr(), split

    def spring_force(self, free: NDArray) -> FrameForce | None:
        """The springs' forces k_i u_i(t) over the ``free`` (n_u,) DOFs, or None without
        springs."""
        if self.springs is None:
            return None
        s, dofs = self.springs, self.springs.dofs()
        forces = s.targets.reshape(len(s.targets), -1) * np.repeat(s.stiffness, 3)
        return FrameForce(forces, dofs, np.searchsorted(free, dofs), self.frame_dt, len(free))

    def drive_energy(self, k_diag: NDArray) -> float:
        """Energy scale of the drive, J: the largest 0.5 sum_i K_ii u_i^2 of a frame's
        prescribed displacements (K_ii: the stiffness' diagonal ``k_diag`` (n,) N/m), or of
        a frame's spring targets if larger."""
        n_fix = 3 * self.fixed_idx.size
        k_diag = k_diag[self.prescribed_dofs]
        u = np.hstack([self.values, np.zeros((self.n_frames, n_fix))])
        energy = 0.5 * float(((u**2) @ k_diag).max())
        if self.springs is not None:
            s = self.springs
            energy = max(energy, float(0.5 * ((s.targets**2).sum(axis=2) @ s.stiffness).max()))
        return energy


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
