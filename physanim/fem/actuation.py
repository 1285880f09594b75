"""Active stress: the FEM's actuation, muscle-like stresses in the tissue.

Physics (small strain). The total Cauchy stress of a tet is

    sigma = C eps + C' eps_dot + sigma_a,

elastic and viscous (the law, :mod:`physanim.fem.laws`) plus an active stress sigma_a, a Voigt
6-vector (xx, yy, zz, yz, xz, xy; tensor components, not doubled) in Pa, prescribed in time
and independent of the material. Virtual work over the element's strain B_e d puts it on the
right-hand side as the nodal force

    f_a = -sum_e V_e B_e^T sigma_a,e   (N),   M d'' + C d' + K d = f + f_a.

Sign convention: a positive (tensile) active stress along a direction contracts the tissue
along it; an unloaded body settles where the total stress vanishes, at the strain
eps = -C^{-1} sigma_a (uniform for a uniform sigma_a). Both element formulations
(:mod:`physanim.fem.elements`) pass that patch test: the averaged nodal pressure of 'anp'
equals the tets' own volumetric strain under a uniform strain. Because it is a stress, not an
active strain, the same actuation strains a softer tissue more (eps ~ 1/E) and reaches a
more viscous one later (Kelvin-Voigt relaxation time eta / mu): material edits act on it.

Actuation fields (:class:`StressBasis`): P smooth spatial patches over the tissue (a
partition of unity, each patch's weight falling as (1 - (d/r)^2)^2 from its centre) times the
5 orthonormal deviatoric stress directions. The volumetric part of an active stress is left
out: nearly incompressible tissue balances it by its pressure (kappa / mu = 100 at nu =
0.495, so it moves the tissue about a hundred times less). :class:`Actuation` holds the
coefficients (Pa) per capture frame, interpolated between frames like the driven motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit, prange
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from physanim.fem.assembly import strain_displacement
from physanim.fem.boundary import FrameForce, patch_weights
from physanim.fem.geometry import element_dofs
from physanim.fem.model import FemModel

_S2, _S6 = np.sqrt(2.0), np.sqrt(6.0)
#: (5, 6) orthonormal deviatoric stress directions in Voigt order (unit Frobenius norm of the
#: tensor): the two normal differences, then the shears yz, xz, xy
DEVIATORIC = np.array(
    [
        [2 / _S6, -1 / _S6, -1 / _S6, 0, 0, 0],
        [0, 1 / _S2, -1 / _S2, 0, 0, 0],
        [0, 0, 0, 1 / _S2, 0, 0],
        [0, 0, 0, 0, 1 / _S2, 0],
        [0, 0, 0, 0, 0, 1 / _S2],
    ]
)
#: Voigt index (xx, yy, zz, yz, xz, xy) of each tensor component (i, j)
VOIGT_INDEX = np.array([[0, 5, 4], [5, 1, 3], [4, 3, 2]])
#: a patch reaches this many times the centres' spacing (every tet lies in several patches)
RADIUS_PER_SPACING = 2.0
#: a tet that may hold no centre lies within this many spacings of one: well inside a
#: patch's reach, where its weight is over a fifth of the centre's
DEEP_REACH_PER_SPACING = 1.5


def stress_force_operator(
    grads: NDArray, volumes: NDArray, tets: NDArray, n_nodes: int
) -> sp.csr_matrix:
    """D (3N, 6M) with D @ s = sum_e V_e B_e^T s_e, the nodal forces (N) that balance per-tet
    stresses s (M, 6) Pa raveled; the active force is f_a = -D @ sigma_a.ravel().

    grads (M, 4, 3) 1/m shape gradients, volumes (M,) m^3, tets (M, 4)."""
    m = len(tets)
    B = strain_displacement(grads) * volumes[:, None, None]  # (M, 6, 12)
    rows = np.broadcast_to(element_dofs(tets)[:, None, :], B.shape)
    cols = np.broadcast_to(6 * np.arange(m)[:, None, None] + np.arange(6)[:, None], B.shape)
    shape = (3 * n_nodes, 6 * m)
    return sp.csr_matrix((B.ravel(), (rows.ravel(), cols.ravel())), shape=shape)


def model_force_operator(model: FemModel) -> sp.csr_matrix:
    """:func:`stress_force_operator` of an assembled model."""
    return stress_force_operator(model.grads, model.volumes, model.tets, len(model.nodes))


#: a lip tet's offset along the patches' fourth axis, times the centres' spacing: a patch's
#: reach, so a patch weighs tets of one side only (the upper lip, the lower lip or the rest):
#: none spans the lip seam, each lip gets patches of its own
SEAM_LIFT_PER_SPACING = RADIUS_PER_SPACING


def covering_centres(
    points: NDArray, spacing: float, eligible: NDArray | None = None, reach: float | None = None
) -> NDArray:
    """Indices (P,) of patch centres among ``points`` (M, D) m by farthest-point sampling,
    from the point nearest their mean, until every point lies within ``spacing`` m of one.

    ``eligible`` (M,) bool: centres only among these points, until each of them lies within
    ``spacing`` m of one; the others then take further centres only where they lie farther
    than ``reach`` m (default ``spacing``) from every centre."""
    p = np.asarray(points, dtype=np.float64)
    everything = np.arange(len(p))
    pool = everything if eligible is None else np.flatnonzero(eligible)
    if not len(pool):
        pool = everything
    rounds = [(pool, spacing)]
    if len(pool) < len(p):
        rounds.append((everything, reach or spacing))
    first = pool[int(np.argmin(np.linalg.norm(p[pool] - p[pool].mean(axis=0), axis=1)))]
    chosen, dist = [int(first)], np.linalg.norm(p - p[first], axis=1)
    for among, limit in rounds:
        while dist[among].max() > limit:
            nxt = int(among[dist[among].argmax()])
            chosen.append(nxt)
            dist = np.minimum(dist, np.linalg.norm(p - p[nxt], axis=1))
    return np.asarray(chosen, dtype=np.int64)


def seam_lift(tets: NDArray, node_side: NDArray, height: float) -> NDArray:
    """Each tet's offset (M,) m along the patches' fourth axis: ``height`` m on the upper
    lip, minus that on the lower lip, 0 elsewhere (the sign of the sum of its nodes' lip sides
    ``node_side`` (N,), as :mod:`physanim.mesh.seam` labels them: 1 upper, -1 lower, 0
    neither). At ``SEAM_LIFT_PER_SPACING`` times the patches' spacing no patch spans two
    sides."""
    side = np.sign(np.asarray(node_side, dtype=np.float64)[np.asarray(tets)].sum(axis=1))
    return height * side


def _lifted(points: NDArray, lift: NDArray | None) -> NDArray:
    """Points (K, 3) m with their fourth coordinate ``lift`` (K,) m appended (0 without)."""
    p = np.asarray(points, dtype=np.float64)
    return np.c_[p, np.zeros(len(p)) if lift is None else np.asarray(lift, dtype=np.float64)]


@dataclass(frozen=True)
class StressBasis:
    """Active stress fields over M tets spanned by P patches x the 5 ``DEVIATORIC``
    directions: sigma_a (M, 6) = weights @ (c @ DEVIATORIC) for coefficients c (P, 5) Pa.

    ``weights`` (M, P) CSR, a partition of unity (rows sum to 1); ``centres`` (P, 3) m and
    their offsets ``lift`` (P,) m along a fourth axis (:func:`seam_lift`: tets apart in it are
    farther apart, so a patch need not span the lip seam); ``radius`` m, each patch's reach
    in those four coordinates."""

    weights: sp.csr_matrix
    centres: NDArray
    radius: float
    lift: NDArray

    @classmethod
    def patches(
        cls,
        nodes: NDArray,
        tets: NDArray,
        centres: NDArray,
        radius: float,
        tet_lift: NDArray | None = None,
        centre_lift: NDArray | None = None,
    ) -> StressBasis:
        """Patches of ``radius`` m around ``centres`` (P, 3) m over the tets' centroids, with
        the tets' and the centres' fourth coordinates ``tet_lift`` (M,) and ``centre_lift``
        (P,) m (0 without); ValueError when a tet lies in no patch."""
        points = _lifted(
            np.asarray(nodes, dtype=np.float64)[np.asarray(tets)].mean(axis=1), tet_lift
        )
        lifted = _lifted(centres, centre_lift)
        near = cKDTree(lifted).sparse_distance_matrix(
            cKDTree(points), radius, output_type="ndarray"
        )
        w = patch_weights(near["v"], radius)
        weights = sp.csr_matrix((w, (near["j"], near["i"])), shape=(len(points), len(lifted)))
        total = np.asarray(weights.sum(axis=1)).ravel()
        if np.any(total <= 0):
            raise ValueError(
                f"{int((total <= 0).sum())} tets lie in no patch: radius {radius} m is too "
                "small for these centres"
            )
        return cls(sp.diags(1.0 / total) @ weights, lifted[:, :3], float(radius), lifted[:, 3])

    @classmethod
    def covering(
        cls,
        nodes: NDArray,
        tets: NDArray,
        spacing: float,
        tet_lift: NDArray | None = None,
        eligible: NDArray | None = None,
    ) -> StressBasis:
        """Patches centred on tet centroids at most ``spacing`` m from every centroid
        (:func:`covering_centres`, in the four coordinates with ``tet_lift`` (M,) m), each
        reaching ``RADIUS_PER_SPACING`` times that. ``eligible`` (M,) bool: centres only on
        these tets (the others each lie within ``DEEP_REACH_PER_SPACING`` spacings of one)."""
        centroids = np.asarray(nodes, dtype=np.float64)[np.asarray(tets)].mean(axis=1)
        points = _lifted(centroids, tet_lift)
        at = covering_centres(points, spacing, eligible, DEEP_REACH_PER_SPACING * spacing)
        return cls.patches(
            nodes, tets, centroids[at], RADIUS_PER_SPACING * spacing, tet_lift, points[at, 3]
        )

    @property
    def n_patches(self) -> int:
        return len(self.centres)

    @property
    def size(self) -> int:
        """Number of coefficients, 5 P."""
        return len(DEVIATORIC) * self.n_patches

    def stress(self, coefficients: NDArray) -> NDArray:
        """Per-tet active stress (M, 6) Pa of coefficients (P, 5) Pa."""
        return self.weights @ (np.asarray(coefficients) @ DEVIATORIC)

    def force_matrix(self, model: FemModel, nominal: NDArray | None = None) -> sp.csc_matrix:
        """(3N, 5P) active nodal forces of ``model``'s mesh, N per Pa of each coefficient
        (patch-major): column (p, k) is -sum_e w_ep V_e B_e^T DEVIATORIC[k], what
        ``model_force_operator(model)`` makes of that stress field; with ``nominal``
        (5, M, 3, 3), each tet's change of nominal stress per Pa of each direction at a
        deformed state (``NeoHookeanANP.nominal_per_direction`` of
        :mod:`physanim.fem.hyperelastic`), the large-strain forces: node a of tet e gets
        -w_ep V_e nominal[k, e] grad N_a."""
        # per direction k, each tet's 12 nodal forces summed over the patches' tets: a sixth
        # of the products through the (3N, 6M) stress operator and no Kronecker product (a
        # 2 mm demo mesh, 150k tets: 1.2 s against 2.5 s)
        if nominal is None:
            b = strain_displacement(model.grads) * model.volumes[:, None, None]  # (M, 6, 12)
            per_tet = -np.einsum("mij,ki->kmj", b, DEVIATORIC)  # (5, M, 12)
        else:
            per_tet = -np.einsum("m,kmil,mal->kmai", model.volumes, nominal, model.grads)
            per_tet = per_tet.reshape(len(DEVIATORIC), len(model.tets), 12)
        m, n_dirs, p = len(model.tets), len(DEVIATORIC), self.n_patches
        dofs, indptr = element_dofs(model.tets).ravel(), 12 * np.arange(m + 1)
        to_patches = self.weights.T.tocsr()  # (P, M)
        by_direction = [
            to_patches @ sp.csr_matrix((f.ravel(), dofs, indptr), shape=(m, model.n_dofs))
            for f in per_tet
        ]  # each (P, 3N)
        patch_major = (np.arange(p)[:, None] + p * np.arange(n_dirs)).ravel()
        return sp.vstack(by_direction, format="csr")[patch_major].T  # CSC

    def nodal_forces(self, model: FemModel, coefficients: NDArray) -> NDArray:
        """Active nodal forces (T, 3N) N of coefficients (T, P, 5) Pa on ``model``'s mesh:
        ``force_matrix(model)`` times each frame's coefficients, without forming it."""
        c = np.ascontiguousarray(coefficients, dtype=np.float64)
        w = sp.csr_matrix(self.weights)
        out = np.zeros((len(c), model.n_dofs))
        _active_forces(w.indptr, w.indices, w.data, c, DEVIATORIC, model.grads,
                       model.volumes, np.ascontiguousarray(model.tets), out)  # fmt: skip
        return out

    def patch_volumes(self, volumes: NDArray) -> NDArray:
        """Volume (P,) m^3 of each patch, sum_e w_ep V_e (they sum to the tissue's)."""
        return self.weights.T @ np.asarray(volumes, dtype=np.float64)


@dataclass(frozen=True)
class Actuation:
    """Active stress over a run: ``basis`` and its ``coefficients`` (T, P, 5) Pa at the T
    capture frames (Catmull-Rom between them, as the driven motion)."""

    basis: StressBasis
    coefficients: NDArray

    def __post_init__(self) -> None:
        c = self.coefficients
        if c.ndim != 3 or c.shape[1:] != (self.basis.n_patches, len(DEVIATORIC)):
            raise ValueError(
                f"actuation coefficients must be (T, {self.basis.n_patches}, "
                f"{len(DEVIATORIC)}) Pa, got {c.shape}"
            )
        if not np.isfinite(c).all():
            raise ValueError("actuation coefficients contain NaN or Inf")

    @property
    def n_frames(self) -> int:
        return len(self.coefficients)

    def scaled(self, factors: NDArray) -> Actuation:
        """The actuation with each patch's coefficients times ``factors``: (P,) in every
        frame, or (T, P) per frame."""
        f = np.asarray(factors, dtype=np.float64)
        per_frame = f[:, :, None] if f.ndim == 2 else f[None, :, None]
        return Actuation(self.basis, self.coefficients * per_frame)

    def force(self, model: FemModel, free: NDArray, frame_dt: float) -> FrameForce:
        """Active forces f_a (N) on the ``free`` (n_u,) DOFs of ``model`` at the frames."""
        values = self.basis.nodal_forces(model, self.coefficients)[:, free]
        return FrameForce(values, free, np.arange(len(free)), frame_dt, len(free))

    def energy_scale(self, model: FemModel) -> float:
        """Energy scale of the actuation, J: the largest over frames of sum_p V_p |c_p|^2 /
        (4 mu_p), the elastic energy of each patch strained freely by its deviatoric active
        stress (mu_p its volume-averaged shear modulus)."""
        vol = self.basis.patch_volumes(model.volumes)
        mu = (self.basis.weights.T @ (model.volumes * model.mu)) / vol
        per_frame = (self.coefficients**2).sum(axis=2) @ (vol / (4.0 * mu))
        return float(per_frame.max(initial=0.0))


# f_a = -V_e B_e^T sigma_a,e per tet and frame, one frame per thread (no two threads add into
# one row) reading the shape gradients (12 numbers per tet) rather than B (72): on a 2 mm demo
# mesh (150k tets, 90 frames) 0.8-0.9 s where the force matrix and its product took 1.8-2.1 s
@njit(cache=True, parallel=True)
def _active_forces(w_indptr, w_indices, w_data, coef, directions, grads, volumes, tets, out):
    """out (T, 3N) += the nodal forces of the stresses weights @ (coef[t] @ directions)."""
    n_dir = directions.shape[0]
    for t in prange(coef.shape[0]):
        a, s = np.empty(n_dir), np.empty(6)
        for e in range(tets.shape[0]):
            a[:] = 0.0
            for k in range(w_indptr[e], w_indptr[e + 1]):
                for j in range(n_dir):
                    a[j] += w_data[k] * coef[t, w_indices[k], j]
            for i in range(6):  # Voigt xx, yy, zz, yz, xz, xy
                s[i] = 0.0
                for j in range(n_dir):
                    s[i] += a[j] * directions[j, i]
            v = volumes[e]
            for n in range(4):
                gx, gy, gz = grads[e, n, 0], grads[e, n, 1], grads[e, n, 2]
                i = 3 * tets[e, n]
                out[t, i] -= v * (s[0] * gx + s[5] * gy + s[4] * gz)
                out[t, i + 1] -= v * (s[5] * gx + s[1] * gy + s[3] * gz)
                out[t, i + 2] -= v * (s[4] * gx + s[3] * gy + s[2] * gz)
