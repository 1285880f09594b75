"""Vectorised assembly of linear-tet stiffness, mass and viscous damping (scipy.sparse).

DOF layout: 3 DOFs per node, interleaved (x0, y0, z0, x1, ...). Voigt strain order
(xx, yy, zz, yz, xz, xy) with engineering shear strains.
"""

from __future__ import annotations

import hashlib

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from physanim.fem.geometry import element_dofs

#: Voigt form m of the identity: m . eps = tr(eps), the volumetric strain
M_VOIGT = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])


def strain_displacement(grads: np.ndarray) -> np.ndarray:
    """Strain-displacement matrices B (M, 6, 12) from shape gradients (M, 4, 3) in 1/m."""
    n = len(grads)
    B = np.zeros((n, 6, 4, 3))
    gx, gy, gz = grads[..., 0], grads[..., 1], grads[..., 2]
    B[:, 0, :, 0] = gx
    B[:, 1, :, 1] = gy
    B[:, 2, :, 2] = gz
    B[:, 3, :, 1], B[:, 3, :, 2] = gz, gy
    B[:, 4, :, 0], B[:, 4, :, 2] = gz, gx
    B[:, 5, :, 0], B[:, 5, :, 1] = gy, gx
    return B.reshape(n, 6, 12)


def lame(E: np.ndarray, nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shear modulus mu and bulk modulus kappa (Pa), each shaped like E, from E (Pa) and nu."""
    mu = E / (2.0 * (1.0 + nu))
    kappa = E / (3.0 * (1.0 - 2.0 * nu))
    return mu, kappa


def deviatoric_matrix(coef: np.ndarray, normal: float = 2.0) -> np.ndarray:
    """Voigt matrices (M, 6, 6): coef * (diag(a, a, a, 1, 1, 1) - (a/3) m m^T), a = ``normal``.

    With a = 2 this is 2 coef dev(.) for engineering shear strains (isotropic): the
    deviatoric elasticity for coef = mu, the Kelvin-Voigt viscosity for coef = eta.
    With a = 1 and coef = eta it is the seed's C' (SPEC eq 4.26).
    """
    base = np.diag([normal] * 3 + [1.0] * 3) - (normal / 3.0) * np.outer(M_VOIGT, M_VOIGT)
    return coef[:, None, None] * base


def volumetric_matrix(coef: np.ndarray) -> np.ndarray:
    """Voigt matrices (M, 6, 6): coef m m^T (coef = kappa: the volumetric elasticity)."""
    return coef[:, None, None] * np.outer(M_VOIGT, M_VOIGT)


def element_blocks(grads: np.ndarray, volumes: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Element matrices V B^T D B (M, 12, 12) for Voigt material matrices D (M, 6, 6), with
    each tet's B (:func:`strain_displacement`) made from its shape gradients (M, 4, 3) 1/m."""
    out = np.empty((len(grads), 12, 12))
    _element_blocks(np.ascontiguousarray(grads, np.float64), np.asarray(volumes, np.float64),
                    np.ascontiguousarray(D, np.float64), out)  # fmt: skip
    return out


# one pass per tet on numba's threads, B built in it: numpy's einsum over B (M, 6, 12) made
# (M, 6, 12) and (M, 12, 12) temporaries and took 0.65 s per matrix on a 2 mm demo mesh
# (150k tets), this 0.05 s
@njit(cache=True, parallel=True)
def _element_blocks(grads, volumes, D, out):
    for e in prange(grads.shape[0]):
        B = np.zeros((6, 12))  # the layout of strain_displacement
        for a in range(4):
            gx, gy, gz = grads[e, a, 0], grads[e, a, 1], grads[e, a, 2]
            B[0, 3 * a], B[1, 3 * a + 1], B[2, 3 * a + 2] = gx, gy, gz
            B[3, 3 * a + 1], B[3, 3 * a + 2] = gz, gy
            B[4, 3 * a], B[4, 3 * a + 2] = gz, gx
            B[5, 3 * a], B[5, 3 * a + 1] = gy, gx
        db = np.empty((6, 12))  # V D B
        for i in range(6):
            for b in range(12):
                acc = 0.0
                for j in range(6):
                    acc += D[e, i, j] * B[j, b]
                db[i, b] = volumes[e] * acc
        for a in range(12):
            for b in range(12):
                acc = 0.0
                for i in range(6):
                    acc += B[i, a] * db[i, b]
                out[e, a, b] = acc


def assemble(blocks: np.ndarray, tets: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """Sum element blocks (M, 12, 12) into a sparse (3N, 3N) CSR matrix (sorted indices)."""
    indptr, indices, slots = _block_pattern(np.ascontiguousarray(tets), n_nodes)
    data = np.zeros(len(indices))
    _scatter_add(slots, np.ascontiguousarray(blocks, np.float64).reshape(-1), data)
    n = 3 * n_nodes
    return sp.csr_matrix((data, indices, indptr), shape=(n, n))


# np.bincount's weighted sum took 0.25 s per matrix on a 2 mm demo mesh (22M entries)
@njit(cache=True)
def _scatter_add(slots, values, out):
    """out[slots[i]] += values[i] for every i."""
    for i in range(len(slots)):
        out[slots[i]] += values[i]


# K, M and C of a mesh share one pattern: it is found once per mesh, from the node pairs
# (16 per tet, not the 144 DOF pairs whose sort took most of each assembly), and each matrix
# is then a sum into its slots
_PATTERNS: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def _block_pattern(tets: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR indptr (3N + 1,) and indices of the element blocks' union pattern and each block
    entry's slot in it (M * 144,), cached for the last meshes seen.

    DOF row 3 i + a holds, for each node j coupled to i (sorted), columns 3 j + (0, 1, 2):
    node pair slot p of row i puts entry (a, b) at 9 nptr[i] + 3 a deg[i] + 3 p + b."""
    key = (n_nodes, tets.shape, str(tets.dtype), hashlib.blake2b(tets.tobytes()).digest())
    if key not in _PATTERNS:
        nptr, neighbours = _node_pairs(tets.astype(np.int64), n_nodes)
        deg = np.diff(nptr)
        indptr = np.r_[
            (9 * nptr[:-1, None] + 3 * np.arange(3) * deg[:, None]).ravel(), 9 * nptr[-1]
        ]
        slots, indices = _block_slots(tets.astype(np.int64), nptr, neighbours)
        if len(_PATTERNS) >= 2:
            _PATTERNS.pop(next(iter(_PATTERNS)))
        _PATTERNS[key] = (indptr, indices, slots)
    return _PATTERNS[key]


# compiled: np.unique over the 16 M node pairs and the (M, 4, 3, 4, 3) index arithmetic took
# 0.5-0.8 s on a 2 mm demo mesh (150k tets), these two loops 0.2 s
@njit(cache=True)
def _node_pairs(tets, n_nodes):
    """The nodes coupled to each node (itself included) by a tet, sorted: CSR pointers
    nptr (N + 1,) into neighbours."""
    count = np.zeros(n_nodes + 1, np.int64)
    for e in range(tets.shape[0]):
        for a in range(4):
            count[tets[e, a] + 1] += 4
    start = np.cumsum(count)
    fill = start[:-1].copy()
    neighbours = np.empty(start[-1], np.int64)
    for e in range(tets.shape[0]):
        for a in range(4):
            i = tets[e, a]
            for b in range(4):
                neighbours[fill[i]] = tets[e, b]
                fill[i] += 1
    nptr = np.zeros(n_nodes + 1, np.int64)
    size = 0  # each row sorted and its repeats dropped, in place (rows only move down)
    for i in range(n_nodes):
        last = -1
        for j in np.sort(neighbours[start[i] : start[i + 1]]):
            if j != last:
                neighbours[size] = j
                size += 1
                last = j
        nptr[i + 1] = size
    return nptr, neighbours[:size].copy()


@njit(cache=True, parallel=True)
def _block_slots(tets, nptr, neighbours):
    """Each element block entry's slot (M * 144,), blocks in (tet, 3 a + r, 3 b + c) order,
    and the pattern's column indices (9 pairs,); tets sharing an entry write the same
    column there."""
    slots = np.empty(tets.shape[0] * 144, np.int64)
    indices = np.empty(9 * len(neighbours), np.int64)
    for e in prange(tets.shape[0]):
        for a in range(4):
            i = tets[e, a]
            lo, deg = nptr[i], nptr[i + 1] - nptr[i]
            for b in range(4):
                j = tets[e, b]
                p = np.searchsorted(neighbours[lo : lo + deg], j)
                for r in range(3):
                    for c in range(3):
                        at = 9 * lo + 3 * r * deg + 3 * p + c
                        slots[e * 144 + (3 * a + r) * 12 + 3 * b + c] = at
                        indices[at] = 3 * j + c
    return slots, indices


def nodal_volumes(tets: np.ndarray, volumes: np.ndarray, n_nodes: int) -> np.ndarray:
    """Dual volume of each node (N,) in m^3: a quarter of each incident tet's volume."""
    return np.bincount(tets.ravel(), np.repeat(volumes / 4.0, 4), minlength=n_nodes)


def nodal_average(tets: np.ndarray, volumes: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """Operator S (N, M) averaging per-tet values at nodes, weighted by V_e / 4 / V_n."""
    vn = nodal_volumes(tets, volumes, n_nodes)
    w = (volumes[:, None] / 4.0) / vn[tets]  # (M, 4)
    cols = np.repeat(np.arange(len(tets)), 4)
    return sp.coo_matrix((w.ravel(), (tets.ravel(), cols)), shape=(n_nodes, len(tets))).tocsr()


def nodal_divergence(grads: np.ndarray, tets: np.ndarray, S: sp.csr_matrix) -> sp.csr_matrix:
    """Operator G (N, 3N): averaged divergence at nodes, theta_n = (G d)_n (dimensionless).

    theta_n = sum_{e ni n} (V_e / 4) div_e(d) / V_n with the averaging S (N, M) from
    ``nodal_average``; this is the averaged-nodal-pressure volumetric strain.
    """
    n_nodes = S.shape[0]
    g = sp.csr_matrix(
        (grads.reshape(-1), element_dofs(tets).reshape(-1), np.arange(0, 12 * len(tets) + 1, 12)),
        shape=(len(tets), 3 * n_nodes),
    )  # div_e(d) = g_e . d_e
    return (S @ g).tocsr()


def mass_matrix(
    tets: np.ndarray, volumes: np.ndarray, rho: np.ndarray, n_nodes: int, lumped: bool
) -> sp.csr_matrix:
    """Mass matrix (3N, 3N) in kg: consistent rho int N^T N dV, or row-sum lumped (diagonal)."""
    if lumped:
        m_node = nodal_volumes(tets, rho * volumes, n_nodes)
        return sp.diags(np.repeat(m_node, 3)).tocsr()
    indptr, indices, slots = _block_pattern(np.ascontiguousarray(tets), n_nodes)
    data = np.zeros(len(indices))
    _add_mass(slots, np.asarray(rho * volumes, np.float64), data)
    return sp.csr_matrix((data, indices, indptr), shape=(3 * n_nodes, 3 * n_nodes))


# the consistent element mass into its slots, without its (M, 12, 12) blocks (177 MB on a
# 2 mm demo mesh, 0.4-0.6 s)
@njit(cache=True)
def _add_mass(slots, mass, out):
    """out[slot] += mass_e int N_a N_b dV / V_e = mass_e (1 + [a == b]) / 20 on each node
    pair's three diagonal DOF pairs (the blocks' other entries stay zero)."""
    for e in range(len(mass)):
        for a in range(4):
            for b in range(4):
                w = mass[e] * (2.0 if a == b else 1.0) / 20.0
                for r in range(3):
                    out[slots[e * 144 + (3 * a + r) * 12 + 3 * b + r]] += w
