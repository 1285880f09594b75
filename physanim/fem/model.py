"""Assembled viscoelastic FEM model of a tet mesh: K, M, C and per-element operators."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from physanim.fem.assembly import assemble, element_blocks, mass_matrix
from physanim.fem.elements import ELEMENTS, Element, formed
from physanim.fem.geometry import element_dofs, shape_gradients
from physanim.fem.laws import MaterialLaw
from physanim.fem.materials import TetMaterials
from physanim.fem.params import ModelParams


# one pass per tet (strain, deviator, invariant): the numpy version made ~10 temporaries of
# (M, 6) and took ~5 ms per frame on the demo mesh; it reads the shape gradients (M, 4, 3), not
# B (M, 6, 12): 12 instead of 72 numbers per tet from memory, once per output frame
@njit(cache=True, parallel=True)
def _von_mises(grads, d_elem, mu, out):
    """out (M,) = sqrt(3/2 s:s), s = 2 mu dev(eps), eps = sym(sum_a u_a grad N_a^T) for the
    element displacements d_elem (M, 12) (node a's u_a at 3a..3a+2)."""
    for e in prange(grads.shape[0]):
        e0 = e1 = e2 = e3 = e4 = e5 = 0.0
        for a in range(4):
            gx, gy, gz = grads[e, a, 0], grads[e, a, 1], grads[e, a, 2]
            ux, uy, uz = d_elem[e, 3 * a], d_elem[e, 3 * a + 1], d_elem[e, 3 * a + 2]
            e0 += gx * ux
            e1 += gy * uy
            e2 += gz * uz
            e3 += gz * uy + gy * uz  # engineering shears: yz, xz, xy
            e4 += gz * ux + gx * uz
            e5 += gy * ux + gx * uy
        mean = (e0 + e1 + e2) / 3.0
        normal = (e0 - mean) ** 2 + (e1 - mean) ** 2 + (e2 - mean) ** 2
        shear = e3**2 + e4**2 + e5**2
        out[e] = mu[e] * np.sqrt(6.0 * normal + 3.0 * shear)


@dataclass
class FemModel:
    """Linear viscoelastic tet model. Matrices are (3N, 3N) CSR, DOFs interleaved x, y, z.

    K: stiffness, N/m, formed on first use (for 'anp' it couples two rings of nodes: the
    simulation's products and solves use the split, :attr:`split`). M: mass, kg. C: viscous
    damping, N s/m. K_el: the assembled ``k_blocks`` (equal to K for 'p1', the deviatoric
    part for 'anp'). ``formulation``: the element's name; ``mu`` (M,) the law's shear
    modulus, Pa (for the von Mises stress).
    ``k_blocks`` / ``c_blocks`` (M, 12, 12): element stiffness / damping blocks; for the
    'anp' formulation ``k_blocks`` holds only the deviatoric part and the volumetric part is
    G^T diag(w_vol) G with the nodal divergence G (N, 3N) = S (N, M) times the per-tet
    divergence rows (``grads`` (M, 4, 3), 1/m), and w_vol = kappa_n V_n (N,) in N m.
    """

    nodes: np.ndarray
    tets: np.ndarray
    dofs: np.ndarray
    volumes: np.ndarray
    mu: np.ndarray
    formulation: str
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
        _von_mises(self.grads, np.ascontiguousarray(d_elem, dtype=np.float64), self.mu, out)
        return out

    @cached_property
    def K(self) -> sp.csr_matrix:
        return formed(self.K_el, self.G, self.w_vol)

    def stiffness_diagonal(self) -> np.ndarray:
        """diag(K) (3N,) N/m without forming K."""
        k = self.K_el.diagonal()
        return k if self.G is None else k + self.G.power(2).T @ self.w_vol

    @property
    def split(self) -> tuple[sp.csr_matrix, sp.csr_matrix, np.ndarray] | None:
        """(K_el, G, w_vol) with K = K_el + G^T diag(w_vol) G for 'anp', else None."""
        return None if self.G is None else (self.K_el, self.G, self.w_vol)


def build_model(
    nodes: np.ndarray,
    tets: np.ndarray,
    materials: TetMaterials,
    params: ModelParams | None = None,
    *,
    law: MaterialLaw | None = None,
    element: Element | None = None,
) -> FemModel:
    """Assemble K, M, C of a tet mesh (nodes (N, 3) m, tets (M, 4) positively oriented).

    ``law`` (default ``params.law``) and ``element`` (default ``ELEMENTS[params.formulation]``)
    may be any :class:`MaterialLaw` / :class:`Element`.
    """
    params = params or ModelParams()
    law = law or params.law
    element = element or ELEMENTS[params.formulation]
    nodes = np.asarray(nodes, dtype=np.float64)
    tets = np.asarray(tets)
    grads, vol = shape_gradients(nodes, tets)
    mat = materials.validated(len(tets), law.tet_fields)
    n = len(nodes)
    mu, kappa = law.moduli(mat)
    stiff = element.stiffness(grads, vol, tets, n, mu, kappa)
    c_blocks = element_blocks(grads, vol, law.viscosity(mat))
    return FemModel(
        nodes=nodes,
        tets=tets,
        dofs=element_dofs(tets),
        volumes=vol,
        mu=mu,
        formulation=element.name,
        K_el=stiff.K_el,
        M=mass_matrix(tets, vol, mat.rho, n, lumped=params.mass == "lumped"),
        C=assemble(c_blocks, tets, n),
        k_blocks=stiff.k_blocks,
        c_blocks=c_blocks,
        G=stiff.G,
        S=stiff.S,
        w_vol=stiff.w_vol,
        grads=grads,
    )
