"""Corotational (stiffness-warping) elasticity: per-tet rotations by polar decomposition.

Each tet's elastic and viscous forces act on its displacement seen in a frame rotated with
the tet: u_e = R_e^T x_e - X_e (x current, X rest positions). Rotations are taken from the
state at the start of each step and held over the step (linearised warping); the warped
Newmark system is solved by conjugate gradients preconditioned with the rest-pose
factorisation, so no refactorisation per step.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from physanim.fem.model import FemModel
from physanim.fem.newmark import Newmark, State


def rotations(model: FemModel, d: np.ndarray) -> np.ndarray:
    """Rotation R_e (M, 3, 3) of each tet: polar factor of its deformation gradient.

    d: (3N,) displacements in m. Inverted tets get the nearest proper rotation (det = +1).
    """
    x = model.nodes[model.tets] + d[model.dofs].reshape(-1, 4, 3)
    F = np.einsum("mai,maj->mij", x, model.grads)
    U, _, Vt = np.linalg.svd(F)
    flip = np.linalg.det(U) * np.linalg.det(Vt) < 0
    U[flip, :, 2] *= -1.0
    return U @ Vt


def local_displacements(model: FemModel, d: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Element displacements in each tet's rotated frame, u_e = R_e^T x_e - X_e, (M, 12) m."""
    X = model.nodes[model.tets]
    x = X + d[model.dofs].reshape(-1, 4, 3)
    return (np.einsum("mji,maj->mai", R, x) - X).reshape(-1, 12)


def strain_energy(model: FemModel, u_local: np.ndarray) -> float:
    """Elastic energy (J) of element displacements (M, 12) m in the tets' own frames."""
    e = 0.5 * np.einsum("mi,mij,mj->", u_local, model.k_blocks, u_local)
    if model.G is not None:
        theta = model.S @ np.einsum("mi,mi->m", model.grads.reshape(-1, 12), u_local)
        e += 0.5 * float(model.w_vol @ theta**2)
    return float(e)


class CorotationalNewmark(Newmark):
    """Newmark with corotational elastic and viscous forces; same interface as ``Newmark``.

    ``rtol`` / ``max_iter``: PCG relative residual tolerance and iteration cap per step.
    """

    def __init__(
        self,
        model: FemModel,
        dt: float,
        prescribed: np.ndarray,
        solver: str = "auto",
        rtol: float = 1e-8,
        max_iter: int = 100,
    ) -> None:
        super().__init__(model.K, model.M, model.C, dt, prescribed, solver, model.split)
        self.model = model
        self.rtol, self.max_iter = rtol, max_iter
        self._blocks = model.k_blocks + (2.0 / self.dt) * model.c_blocks
        self._g = model.grads.reshape(-1, 12)
        self.iterations: list[int] = []

    def _element_force(self, blocks, R, y, offset=None, vol=True):
        """sum_e P_e^T blocks_e (P_e y_e + offset_e) (+ ANP volumetric part), (3N,) N."""
        m = self.model
        ye = np.einsum("mji,maj->mai", R, y[m.dofs].reshape(-1, 4, 3)).reshape(-1, 12)
        if offset is not None:
            ye += offset
        fe = np.einsum("mij,mj->mi", blocks, ye)
        if vol and m.G is not None:
            theta = m.S @ np.einsum("mi,mi->m", self._g, ye)
            fe += (m.S.T @ (m.w_vol * theta))[:, None] * self._g
        fe = np.einsum("mij,maj->mai", R, fe.reshape(-1, 4, 3)).reshape(-1)
        return np.bincount(m.dofs.ravel(), fe, minlength=m.n_dofs)

    def dissipation(self, delta: np.ndarray) -> float:
        """Viscous energy (J) dissipated over the last step, in the step's rotated frames."""
        f = self._element_force(self.model.c_blocks, self._R, delta, vol=False)
        return float(delta @ f) / self.dt

    def step(
        self,
        state: State,
        d_c: np.ndarray,
        v_c: np.ndarray,
        a_c: np.ndarray,
        f_u: np.ndarray | None = None,
    ) -> State:
        """Advance ``state`` in place by dt; rotations from the state at the step start."""
        m, dt, u, c = self.model, self.dt, self.free, self.prescribed
        R = self._R = rotations(m, state.d)
        X = m.nodes[m.tets]
        offset = (np.einsum("mji,maj->mai", R, X) - X).reshape(-1, 12)  # (P_e - I) X_e
        n = m.n_dofs
        a_bar, v_bar, d_bar = np.zeros(n), np.zeros(n), np.zeros(n)
        a_bar[u] = -((4.0 / dt**2) * state.d[u] + (4.0 / dt) * state.v[u] + state.a[u])
        v_bar[u] = -((2.0 / dt) * state.d[u] + state.v[u])
        a_bar[c], v_bar[c], d_bar[c] = a_c, v_c, d_c
        rhs = -(
            m.M @ a_bar
            + self._element_force(m.c_blocks, R, v_bar, vol=False)
            + self._element_force(m.k_blocks, R, d_bar, offset)
        )[u]
        if f_u is not None:
            rhs += f_u
        c0 = 4.0 / dt**2

        def matvec(x_u: np.ndarray) -> np.ndarray:
            y = np.zeros(n)
            y[u] = x_u
            return (c0 * (m.M @ y) + self._element_force(self._blocks, R, y))[u]

        shape = (self.free.size, self.free.size)
        op = spla.LinearOperator(shape, matvec=matvec, dtype=np.float64)
        pre = spla.LinearOperator(shape, matvec=self.solve, dtype=np.float64)
        count = [0]

        def cb(_: np.ndarray) -> None:
            count[0] += 1

        d_u, info = spla.cg(
            op,
            rhs,
            x0=state.d[u],
            rtol=self.rtol,
            atol=0.0,
            maxiter=self.max_iter,
            M=pre,
            callback=cb,
        )
        if info != 0:
            raise RuntimeError(
                f"corotational PCG did not reach rtol {self.rtol} in {self.max_iter} iterations; "
                "reduce dt or raise corot_max_iter"
            )
        self.iterations.append(count[0])
        a_u = c0 * (d_u - state.d[u]) - (4.0 / dt) * state.v[u] - state.a[u]
        state.v[u] += 0.5 * dt * (state.a[u] + a_u)
        state.a[u] = a_u
        state.d[u] = d_u
        state.d[c], state.v[c], state.a[c] = d_c, v_c, a_c
        return state
