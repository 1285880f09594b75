"""Forward kinematics: joint frames, capsule end points and centre of mass."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physanim.dynamics.figure import Figure
from physanim.dynamics.kernels import fk_batch


@dataclass(frozen=True)
class Kinematics:
    """Joint frames in the world, for one pose (leading shape ``()``) or a batch ``(T,)``.

    ``positions`` (..., n, 3) m: joint origins; ``rotations`` (..., n, 3, 3): link frames.
    """

    positions: np.ndarray
    rotations: np.ndarray


def _as_batch(fig: Figure, q: np.ndarray, name: str = "q") -> tuple[np.ndarray, bool]:
    """Return q as a C-contiguous (B, n) float array and whether the input was 1-D."""
    q = np.asarray(q, dtype=float)
    single = q.ndim == 1
    q2 = np.ascontiguousarray(q[None] if single else q)
    if q2.ndim != 2 or q2.shape[1] != fig.n_dof:
        raise ValueError(
            f"{name} must have shape ({fig.n_dof},) or (T, {fig.n_dof}) for figure "
            f"{fig.name!r}, got {q.shape}"
        )
    return q2, single


def forward_kinematics(
    fig: Figure,
    q: np.ndarray,
    *,
    base_pos: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
    base_rot: np.ndarray | None = None,
) -> Kinematics:
    """World joint frames for angles ``q`` (n,) or (T, n) rad.

    ``base_pos`` (3,) or (T, 3) m places the base origin; ``base_rot`` (3, 3) orients it
    (default identity).
    """
    q2, single = _as_batch(fig, q)
    bp = np.ascontiguousarray(np.broadcast_to(np.asarray(base_pos, float), (len(q2), 3)))
    br = np.eye(3) if base_rot is None else np.ascontiguousarray(base_rot, dtype=float)
    rot, pos = fk_batch(fig.parent, fig.axis, fig.offset, q2, bp, br)
    if single:
        return Kinematics(pos[0], rot[0])
    return Kinematics(pos, rot)


def capsule_segments(fig: Figure, kin: Kinematics) -> tuple[np.ndarray, np.ndarray]:
    """Capsule axis end points (start, end), each (..., n, 3) m, in the world."""
    end = kin.positions + np.einsum("...ij,...j->...i", kin.rotations, fig.tips)
    return kin.positions, end


def link_coms(fig: Figure, kin: Kinematics) -> np.ndarray:
    """World centre of mass of every link, (..., n, 3) m."""
    return kin.positions + np.einsum("...ij,...j->...i", kin.rotations, fig.com)


def center_of_mass(fig: Figure, kin: Kinematics) -> np.ndarray:
    """Whole-figure centre of mass, (..., 3) m."""
    return np.einsum("n,...ni->...i", fig.mass, link_coms(fig, kin)) / fig.total_mass
