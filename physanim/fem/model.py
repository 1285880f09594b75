"""Assembled viscoelastic FEM model of a tet mesh: K, M, C and per-element operators."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from physanim.fem.assembly import (
    assemble,
    deviatoric_matrix,
    element_blocks,
    lame,
    mass_matrix,
    nodal_average,
    nodal_divergence,
    nodal_volumes,
    strain_displacement,
)
from physanim.fem.geometry import element_dofs, shape_gradients
from physanim.fem.materials import TetMaterials
from physanim.fem.params import SimulateParams

_M_VOIGT = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])


# one pass per tet (strain, deviator, invariant): the numpy version made ~10 temporaries of
# (M, 6) and took ~5 ms per frame on the demo mesh
@njit(cache=True, parallel=True)
def _von_mises(B, d_elem, mu, out):
    """out (M,) = sqrt(3/2 s:s), s = 2 mu dev(eps), eps = B d_elem (Voigt, engineering shear)."""
    for e in prange(B.shape[0]):
        e0 = e1 = e2 = e3 = e4 = e5 = 0.0
        for j in range(12):
            dj = d_elem[e, j]
            e0 += B[e, 0, j] * dj
            e1 += B[e, 1, j] * dj
            e2 += B[e, 2, j] * dj
            e3 += B[e, 3, j] * dj
            e4 += B[e, 4, j] * dj
            e5 += B[e, 5, j] * dj
        mean = (e0 + e1 + e2) / 3.0
        normal = (e0 - mean) ** 2 + (e1 - mean) ** 2 + (e2 - mean) ** 2
        shear = e3**2 + e4**2 + e5**2
        out[e] = mu[e] * np.sqrt(6.0 * normal + 3.0 * shear)


@dataclass
class FemModel:
    """Linear viscoelastic tet model. Matrices are (3N, 3N) CSR, DOFs interleaved x, y, z.

    K: stiffness, N/m. M: mass, kg. C: viscous damping, N s/m. K_el: the assembled
    ``k_blocks`` (equal to K for 'p1', the deviatoric part for 'anp').
    ``k_blocks`` / ``c_blocks`` (M, 12, 12): element stiffness / damping blocks; for the
    'anp' formulation ``k_blocks`` holds only the deviatoric part and the volumetric part is
    G^T diag(w_vol) G with the nodal divergence G (N, 3N) = S (N, M) times the per-tet
    divergence rows (``grads`` (M, 4, 3), 1/m), and w_vol = kappa_n V_n (N,) in N m.
    """

    nodes: np.ndarray
    tets: np.ndarray
    dofs: np.ndarray
    volumes: np.ndarray
    B: np.ndarray
    mu: np.ndarray
    formulation: str
    K: sp.csr_matrix
    K_el: sp.csr_matrix
    M: sp.csr_matrix
    C: sp.csr_matrix
    k_blocks: np.ndarray
    c_blocks: np.ndarray
    G: sp.csr_matrix | None
    S: sp.csr_matrix | None
    w_vol: np.ndarray | None
    grads: np.ndarray

    @property
    def n_dofs(self) -> int:
        return 3 * len(self.nodes)

    def von_mises(self, d_elem: np.ndarray) -> np.ndarray:
        """Elastic von Mises stress (M,) in Pa from element displacements (M, 12) in m."""
        out = np.empty(len(self.tets))
        _von_mises(self.B, np.ascontiguousarray(d_elem, dtype=np.float64), self.mu, out)
        return out

    @property
    def split(self) -> tuple[sp.csr_matrix, sp.csr_matrix, np.ndarray] | None:
        """(K_el, G, w_vol) with K = K_el + G^T diag(w_vol) G for 'anp', else None."""
        return None if self.G is None else (self.K_el, self.G, self.w_vol)


def build_model(
    nodes: np.ndarray,
    tets: np.ndarray,
    materials: TetMaterials,
    params: SimulateParams | None = None,
) -> FemModel:
    """Assemble K, M, C of a tet mesh (nodes (N, 3) m, tets (M, 4) positively oriented)."""
    params = params or SimulateParams()
    nodes = np.asarray(nodes, dtype=np.float64)
    tets = np.asarray(tets)
    grads, vol = shape_gradients(nodes, tets)
    mat = materials.validated(len(tets))
    n = len(nodes)
    B = strain_displacement(grads)
    mu, kappa = lame(mat.E, mat.nu)
    D = deviatoric_matrix(mu)
    G = S = w_vol = None
    if params.formulation == "p1":
        D = D + kappa[:, None, None] * np.outer(_M_VOIGT, _M_VOIGT)
    k_blocks = element_blocks(B, vol, D)
    K = K_el = assemble(k_blocks, tets, n)
    if params.formulation == "anp":
        S = nodal_average(tets, vol, n)
        G = nodal_divergence(grads, tets, S)
        w_vol = nodal_volumes(tets, kappa * vol, n)  # kappa_n V_n, volume-averaged kappa
        K = (K + G.T @ sp.diags(w_vol) @ G).tocsr()
    normal = 2.0 if params.viscosity == "isotropic" else 1.0
    c_blocks = element_blocks(B, vol, deviatoric_matrix(mat.eta, normal))
    C = assemble(c_blocks, tets, n)
    M = mass_matrix(tets, vol, mat.rho, n, lumped=params.mass == "lumped")
    return FemModel(
        nodes=nodes,
        tets=tets,
        dofs=element_dofs(tets),
        volumes=vol,
        B=B,
        mu=mu,
        formulation=params.formulation,
        K=K,
        K_el=K_el,
        M=M,
        C=C,
        k_blocks=k_blocks,
        c_blocks=c_blocks,
        G=G,
        S=S,
        w_vol=w_vol,
        grads=grads,
    )
