"""The jaw as a moving boundary: its hinge axis and opening angle from tracked points.

The mandible turns about the temporomandibular (TMJ) axis, behind the face.  Given the
head-fixed trajectories of points that move rigidly with the mandible (tracked landmarks on
the chin, or the fitted motion mesh's chin vertices), :func:`estimate_jaw` finds one fixed
axis (a unit direction and a point on it) and the opening angle of every frame by least
squares:

    min over axis, pivot, theta_t of  sum_t sum_k |R(axis, theta_t)(x_k,0 - p) + p - x_k,t|^2

started from per-frame rigid fits (Kabsch).  The pivot is determined by the curvature of the
points' arcs, so its accuracy grows with the largest opening angle.

:func:`mandible_weights` says how much each bone-side point moves with the mandible (0 on the
skull, 1 on the mandible, smoothly between, so no stress singularity appears where they meet)
and :func:`jaw_displacements` moves those points by the estimated rotation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from physanim.mesh.seam import MouthLine


class JawEstimateError(ValueError):
    """Too few or degenerate mandible points to estimate the jaw motion."""


@dataclass(frozen=True)
class JawMotion:
    """Jaw hinge: ``pivot`` (3,) m on the axis, unit ``axis`` (3,) (opening is a positive
    rotation about it), ``angle`` (T,) rad per frame (0 at frame 0), ``residual_m`` (T,) RMS
    misfit of the mandible points per frame, m."""

    pivot: NDArray
    axis: NDArray
    angle: NDArray
    residual_m: NDArray

    def rotations(self) -> NDArray:
        """(T, 3, 3) rotation matrices of the mandible per frame."""
        return Rotation.from_rotvec(self.angle[:, None] * self.axis).as_matrix()


def _rotate(points: NDArray, pivot: NDArray, axis: NDArray, angle: NDArray) -> NDArray:
    """Points (K, 3) turned about (pivot, axis) by each angle (T,) -> (T, K, 3)."""
    rot = Rotation.from_rotvec(np.asarray(angle)[:, None] * axis).as_matrix()
    return np.einsum("tij,kj->tki", rot, points - pivot) + pivot


@dataclass(frozen=True)
class JawPrior:
    """Anatomical prior of the hinge: ``pivot`` (3,) m (the TMJ axis, behind the face) with
    standard deviation ``pivot_std_m``, and never farther than ``pivot_bound_std`` of them
    from it in any coordinate; ``axis`` (3,) unit (the head's left-right axis) with angular
    standard deviation ``axis_std_rad``; ``noise_m``: tracking noise per coordinate."""

    pivot: NDArray
    pivot_std_m: float = 0.01
    axis: NDArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    axis_std_rad: float = 0.17
    noise_m: float = 5e-4
    pivot_bound_std: float = 3.0


def _axis_from(tilt: NDArray, base: NDArray) -> NDArray:
    """Unit axis: ``base`` (3,) turned by the small rotation vector ``tilt`` (2,) about the two
    directions normal to it."""
    u = np.cross(base, [0.0, 0.0, 1.0] if abs(base[2]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(base, u)
    return Rotation.from_rotvec(tilt[0] * u + tilt[1] * v).apply(base)


def estimate_jaw(points: NDArray, prior: JawPrior) -> JawMotion:
    """Hinge axis, pivot and per-frame angle from mandible points (T, K, 3) m, head-fixed frame.

    Frame 0 is the closed (reference) pose; NaN marks a point not seen in a frame (frame 0
    must see them all).  Least squares over the pivot, the axis and every angle, with the
    anatomical ``prior`` on pivot and axis: points on the chin alone barely tell a turn about
    a far pivot from one about a nearer pivot with a larger angle, so the prior decides what
    the data cannot.  The pivot stays within the prior's bound: chin skin that moves while
    the jaw stays (a lip press) was read as a 7 degree turn about a pivot 50 mm in front of
    the TMJ, and the mandible, turned by it, pulled the lips.  Raises JawEstimateError on too
    few points.
    """
    x = np.asarray(points, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3 or x.shape[1] < 2:
        raise JawEstimateError(
            f"need (T, K >= 2, 3) mandible points to estimate the jaw, got shape {x.shape}"
        )
    valid = np.isfinite(x).all(axis=2)
    if not valid[0].all():
        raise JawEstimateError("every mandible point must be seen in frame 0 (the reference)")
    rest, seen = x[0], np.nan_to_num(x)
    n_t = len(x)
    base = np.asarray(prior.axis, dtype=np.float64) / np.linalg.norm(prior.axis)
    p0 = np.asarray(prior.pivot, dtype=np.float64)

    def unpack(z: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        return z[:3], _axis_from(z[3:5], base), np.r_[0.0, z[5:]]

    def residuals(z: NDArray) -> NDArray:
        pivot, axis, angle = unpack(z)
        fit = _rotate(rest, pivot, axis, angle)
        data = np.where(valid[..., None], fit - seen, 0.0)[1:].ravel() / prior.noise_m
        return np.r_[data, (pivot - p0) / prior.pivot_std_m, z[3:5] / prior.axis_std_rad]

    z0 = np.r_[p0, 0.0, 0.0, np.zeros(n_t - 1)]
    # start the angles from a fit about the prior hinge
    z0[5:] = _angles_about(rest, x, valid, p0, base)[1:]
    # each frame's residuals depend on the 5 hinge parameters and that frame's angle only: a
    # sparse Jacobian (6 grouped differences instead of T + 4, no dense SVD of a
    # (3 K T) x (T + 4) matrix in the trust region, which took seconds on the demo)
    reach = np.full(len(z0), np.inf)
    reach[:3] = prior.pivot_bound_std * prior.pivot_std_m
    sol = least_squares(
        residuals, z0, x_scale="jac", jac_sparsity=_jaw_sparsity(rest.shape[0], n_t),
        tr_solver="lsmr", bounds=(z0 - reach, z0 + reach),
    )  # fmt: skip
    pivot, axis, angle = unpack(sol.x)
    fitted = _rotate(rest, pivot, axis, angle)
    sq = np.where(valid, ((fitted - seen) ** 2).sum(axis=2), 0.0)
    residual = np.sqrt(sq.sum(axis=1) / np.maximum(valid.sum(axis=1), 1))
    return JawMotion(pivot, axis, angle, residual)


def _jaw_sparsity(n_points: int, n_frames: int) -> sp.csr_matrix:
    """Nonzero pattern of the jaw residuals' Jacobian: rows (frames 1..T-1 x K points x 3,
    then 3 pivot and 2 axis priors), columns (pivot 3, axis tilt 2, angles T - 1)."""
    per_frame = 3 * n_points
    rows = np.arange((n_frames - 1) * per_frame)
    frame = rows // per_frame
    hinge = sp.csr_matrix(np.ones((len(rows), 5)))
    angles = sp.csr_matrix((np.ones(len(rows)), (rows, frame)), (len(rows), n_frames - 1))
    data = sp.hstack([hinge, angles])
    prior = sp.hstack([sp.eye(5), sp.csr_matrix((5, n_frames - 1))])
    return sp.vstack([data, prior]).tocsr()


def _angles_about(
    rest: NDArray, x: NDArray, valid: NDArray, pivot: NDArray, axis: NDArray
) -> NDArray:
    """Least-squares angle (T,) rad of each frame about the fixed axis through ``pivot``."""
    a = rest - pivot
    a = a - np.outer(a @ axis, axis)
    b = np.nan_to_num(x) - pivot
    b = b - (b @ axis)[..., None] * axis
    w = valid.astype(np.float64)
    sin = (w * (np.cross(a[None], b) @ axis)).sum(axis=1)
    cos = (w * np.einsum("kj,tkj->tk", a, b)).sum(axis=1)
    return np.arctan2(sin, cos)


def mandible_weights(points: NDArray, mouth: MouthLine, blend_m: float) -> NDArray:
    """How much each point (N, 3) m moves with the mandible: (N,) in [0, 1].

    0 above the mouth line (skull), rising smoothly (C1 smoothstep) to 1 at ``blend_m`` below
    it (mandible), across the whole width of the face.
    """
    depth = (mouth.height_at(points[:, 0]) - points[:, 1]) / blend_m
    s = np.clip(depth, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def neighbour_share(tets: NDArray, members: NDArray, n_nodes: int) -> NDArray:
    """(n_nodes,) in [0, 1]: the mean, over each node's tets (M, 4), of the fraction of their
    nodes that are ``members`` (node ids); 0 for nodes in no tet."""
    is_member = np.zeros(n_nodes)
    is_member[members] = 1.0
    tet_share = np.repeat(is_member[tets].mean(axis=1), tets.shape[1])
    total = np.bincount(tets.ravel(), weights=tet_share, minlength=n_nodes)
    return total / np.maximum(np.bincount(tets.ravel(), minlength=n_nodes), 1)


def jaw_displacements(points: NDArray, weights: NDArray, jaw: JawMotion) -> NDArray:
    """Displacements (T, N, 3) m of points (N, 3) m that follow the jaw with ``weights`` (N,)."""
    turn = jaw.rotations() - np.eye(3)  # (R - I) (x - p): exactly 0 where the angle is 0
    return weights[None, :, None] * np.einsum("tij,kj->tki", turn, points - jaw.pivot)
