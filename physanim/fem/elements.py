"""Element formulations of the 4-node tet: how the stiffness is assembled from the moduli.

An element is a small object whose ``stiffness`` turns per-tet moduli into the assembled
stiffness; ``ELEMENTS`` maps ``SimulateParams.formulation`` names onto them. Thick-walled
cylinder accuracy of both: :mod:`physanim.fem` (package docstring).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from physanim.fem.assembly import (
    assemble,
    deviatoric_matrix,
    element_blocks,
    nodal_average,
    nodal_divergence,
    nodal_volumes,
    volumetric_matrix,
)


@dataclass(frozen=True)
class Stiffness:
    """``k_blocks`` (M, 12, 12) element blocks and their assembly K_el (3N, 3N) N/m; with
    averaged nodal pressure the stiffness is K = K_el + G^T diag(w_vol) G (G (N, 3N),
    S (N, M), w_vol (N,) N m), else G, S, w_vol are None and K = K_el (:func:`formed`)."""

    K_el: sp.csr_matrix
    k_blocks: np.ndarray
    G: sp.csr_matrix | None = None
    S: sp.csr_matrix | None = None
    w_vol: np.ndarray | None = None


def formed(K_el: sp.csr_matrix, G: sp.csr_matrix | None, w: np.ndarray | None) -> sp.csr_matrix:
    """K = K_el + G^T diag(w) G (3N, 3N) CSR, or K_el when G is None. The product couples
    two rings of nodes (a 2 mm demo mesh: 17M entries against K_el's 3.7M, 1.3 s to form):
    products and solves take the split form where they can."""
    return K_el if G is None else (K_el + G.T @ sp.diags(w) @ G).tocsr()


class Element(ABC):
    """A tet element formulation; ``name`` is its ``SimulateParams.formulation`` value."""

    name: str

    @abstractmethod
    def stiffness(
        self,
        grads: np.ndarray,
        volumes: np.ndarray,
        tets: np.ndarray,
        n_nodes: int,
        mu: np.ndarray,
        kappa: np.ndarray,
    ) -> Stiffness:
        """Stiffness from shape gradients (M, 4, 3) 1/m, volumes (M,) m^3, tets (M, 4) and
        shear / bulk moduli mu, kappa (M,) Pa."""


class PlainTet(Element):
    """Plain 4-node tet: isotropic elasticity per tet (locks near nu = 0.5, as the seed)."""

    name = "p1"

    def stiffness(self, grads, volumes, tets, n_nodes, mu, kappa) -> Stiffness:
        D = deviatoric_matrix(mu) + volumetric_matrix(kappa)
        k_blocks = element_blocks(grads, volumes, D)
        return Stiffness(K_el=assemble(k_blocks, tets, n_nodes), k_blocks=k_blocks)


class AveragedNodalPressureTet(Element):
    """4-node tet with averaged nodal pressure: the volumetric strain averaged at nodes
    (K = K_dev + G^T diag(kappa_n V_n) G, same DOFs, SPD, locking-free near nu = 0.5)."""

    name = "anp"

    def stiffness(self, grads, volumes, tets, n_nodes, mu, kappa) -> Stiffness:
        k_blocks = element_blocks(grads, volumes, deviatoric_matrix(mu))
        K_el = assemble(k_blocks, tets, n_nodes)
        S = nodal_average(tets, volumes, n_nodes)
        G = nodal_divergence(grads, tets, S)
        w_vol = nodal_volumes(tets, kappa * volumes, n_nodes)  # kappa_n V_n, volume-averaged
        return Stiffness(K_el=K_el, k_blocks=k_blocks, G=G, S=S, w_vol=w_vol)


ELEMENTS: dict[str, Element] = {e.name: e for e in (PlainTet(), AveragedNodalPressureTet())}
