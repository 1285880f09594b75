"""Large-strain elasticity of the tet FEM: isochoric neo-Hookean shear with the averaged
nodal pressure on ln J, and its static solve under dead loads (the actuation's forces).

Why: the linear law keeps the trace of its small strain near zero where nearly
incompressible tissue stretches, so a lip edge stretched s times thins to 2 - s of its
thickness and turns inside out beyond s = 2 (docs/VALIDATION.md, issue #32). This law keeps
the volume of every tet: its energy grows without bound as a tet's volume goes to zero.

Energy (J) of displacements d (3N,) m, F_e = I + sum_a u_a grad N_a^T per tet, J_e = det F_e:

    E(d) = sum_e V_e mu_e / 2 (J_e^(-2/3) tr(F_e^T F_e) - 3) + 1/2 sum_n w_n theta_n^2,
    theta = S ln J   (the nodal average of each tet's ln J_e),

with the model's shear modulus mu (M,) Pa, nodal averaging S (N, M) and w = kappa_n V_n (N,)
N m of the 'anp' element (:mod:`physanim.fem.elements`). For small strain it is the linear
'anp' model's energy (ln J -> tr eps, the isochoric term -> mu |dev eps|^2): the same
stiffness at rest. Dead loads f (N) enter as -f . d.

Active stress (:mod:`physanim.fem.actuation`'s sigma_a per tet) is a second Piola-Kirchhoff
stress S_a held in each tet's material frame, with energy

    E_a(d) = sum_e V_e / 2 S_a,e : (F_e^T F_e - I),   nominal stress F_e S_a,e,

so it turns with the tissue (a rotated tet feels no torque from it, where a stress held in
the rest configuration would twist it), and for small strain it is the linear model's active
stress: E_a -> sum_e V_e S_a,e : eps_e, the nodal forces -sum_e V_e B_e^T S_a,e.

An active stress has a limit: along a direction where S_a is a compression (an eigenvalue
s < 0), a homogeneous stretch lam of incompressible tissue has energy ~ (mu + s) lam^2 / 2 for
large lam, so beyond s = -mu nothing in the tet resists the stretch and only its
neighbours hold it. Active *strain* (``actuation="strain"``) has no such limit: the tissue's
rest shape itself changes, F = F_e F_a, with the isochoric active strain

    F_a = expm(eps_a),  eps_a = -sigma_a / (2 mu)   (symmetric, trace-free: det F_a = 1),

and the shear energy of the elastic part F_e = F F_a^-1,
tr(F_e^T F_e) = F : (F G), G = (F_a F_a^T)^-1 = expm(sigma_a / mu). The actuation is given
in the same units (Pa, the active stress it is at small strain: eps_a -> -C^-1 sigma_a for the
trace-free part, mu each tet's shear modulus in the model), so one field of coefficients
drives either form, and on an edited material acts as the active stress does at small strain.
Its energy is the neo-Hookean energy of F_e, bounded below for any actuation: a free tet
relaxes to F = F_a.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from physanim.fem.actuation import DEVIATORIC, VOIGT_INDEX
from physanim.fem.assembly import assemble
from physanim.fem.linsolve import SymmetricFactors
from physanim.fem.model import FemModel
from physanim.fem.statics import free_dofs

#: Armijo constant and smallest step of the Newton line search
ARMIJO, MIN_STEP = 1e-4, 1e-8
#: the forms of the actuation (module docstring)
ACTUATIONS = ("stress", "strain")


def tensors(voigt: NDArray) -> NDArray:
    """Symmetric tensors (M, 3, 3) of Voigt 6-vectors (M, 6) (tensor components, not doubled
    shears)."""
    return np.asarray(voigt, dtype=np.float64)[:, VOIGT_INDEX]


def _strain_map(grads: NDArray) -> NDArray:
    """(M, 9, 12): row-major F_ij per node DOF (a, k), dF_ij / du_ak = delta_ik grad_a,j."""
    m = len(grads)
    out = np.zeros((m, 3, 3, 4, 3))
    for i in range(3):
        out[:, i, :, :, i] = grads.transpose(0, 2, 1)
    return out.reshape(m, 9, 12)


@dataclass(frozen=True)
class NeoHookeanANP:
    """The module's energy on an assembled 'anp' :class:`FemModel` (its mu, S, w_vol), with
    the actuation as an active ``"stress"`` or an active ``"strain"`` (module docstring)."""

    model: FemModel
    actuation: str = "stress"
    #: the last actuation's strain metric (``_strain_metric``): a static solve evaluates the
    #: energy many times under one actuation, and the eigendecompositions took a tenth of it
    _last_metric: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.model.G is None:
            raise ValueError("the large-strain law needs the 'anp' element formulation")
        if self.actuation not in ACTUATIONS:
            raise ValueError(f"actuation must be one of {ACTUATIONS}, not {self.actuation!r}")

    def deformation(self, d: NDArray) -> tuple[NDArray, NDArray]:
        """Deformation gradients F (M, 3, 3) and their determinants J (M,) of d (3N,) m."""
        m = self.model
        u = np.asarray(d, dtype=np.float64)[m.dofs].reshape(-1, 4, 3)
        F = np.eye(3) + np.einsum("mai,maj->mij", u, m.grads)
        return F, np.linalg.det(F)

    def toward(self, d: NDArray, target: NDArray) -> NDArray:
        """The point on the way from ``d`` to ``target`` (3N,) m, the way halved until no tet
        is inside out (``d`` itself where even 1e-8 of it inverts one)."""
        t, move = 1.0, np.asarray(target) - d
        while np.any(self.deformation(d + t * move)[1] <= 0):
            if t < MIN_STEP:
                return np.array(d, dtype=np.float64)
            t /= 2
        return d + t * move

    def _strain_metric(self, active: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """G = expm(sigma_a / mu) (M, 3, 3) of the active strain, with the eigenvalues
        (M, 3) and eigenvectors (M, 3, 3) of sigma_a / mu."""
        last = self._last_metric
        if "active" in last and np.array_equal(last["active"], active):
            return last["metric"]
        lam, Q = np.linalg.eigh(tensors(active) / self.model.mu[:, None, None])
        metric = np.einsum("mij,mj,mkj->mik", Q, np.exp(lam), Q), lam, Q
        last.update(active=np.array(active, dtype=np.float64), metric=metric)
        return metric

    def energy(self, d: NDArray, f: NDArray | None = None, active: NDArray | None = None) -> float:
        """E(d) + E_a(d) - f . d in J for the actuation ``active`` (M, 6) Pa (Voigt); inf
        where any tet is inverted or flat (J <= 0)."""
        F, J = self.deformation(d)
        if np.any(J <= 0):
            return float("inf")
        m = self.model
        strain = active is not None and self.actuation == "strain"
        FG = F @ self._strain_metric(active)[0] if strain else F
        shear = m.volumes * m.mu / 2 * (J ** (-2 / 3) * np.einsum("mij,mij->m", F, FG) - 3)
        theta = m.S @ np.log(J)
        total = float(shear.sum() + 0.5 * m.w_vol @ theta**2)
        if active is not None and not strain:
            green = np.einsum("mki,mkj->mij", F, F) - np.eye(3)
            total += 0.5 * float(m.volumes @ np.einsum("mij,mij->m", tensors(active), green))
        return total - (0.0 if f is None else float(np.asarray(f) @ d))

    def _scatter(self, P: NDArray) -> NDArray:
        """Nodal forces (3N,) N of per-tet nominal stresses times volume P (M, 3, 3) N m."""
        m = self.model
        fe = np.einsum("mk,mkl->ml", P.reshape(-1, 9), _strain_map(m.grads))
        return np.bincount(m.dofs.ravel(), fe.ravel(), minlength=m.n_dofs)

    def active_forces(self, d: NDArray, active: NDArray) -> NDArray:
        """The nodal forces (3N,) N the actuation ``active`` (M, 6) Pa adds at d (3N,) m:
        minus its change of the energy's gradient."""
        m = self.model
        F, J = self.deformation(d)
        V = m.volumes[:, None, None]
        if self.actuation == "stress":
            return -self._scatter(V * (F @ tensors(active)))
        # the shear's nominal stress with G, less that with I (the pressure does not change)
        FdG = F @ (self._strain_metric(active)[0] - np.eye(3))
        i1 = np.einsum("mij,mij->m", F, FdG)
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        scale = (m.volumes * m.mu * J ** (-2 / 3))[:, None, None]
        return -self._scatter(scale * (FdG - (i1 / 3)[:, None, None] * FiT))

    def nominal_per_direction(self, d: NDArray, active: NDArray | None = None) -> NDArray:
        """(5, M, 3, 3): each tet's change of nominal stress (Pa) per Pa of each
        DEVIATORIC direction of the actuation, at d (3N,) m and the actuation ``active``
        (M, 6) Pa (for an active stress it does not depend on it): what
        ``StressBasis.force_matrix`` takes for the forces per coefficient."""
        F, J = self.deformation(d)
        S_k = DEVIATORIC[:, VOIGT_INDEX]  # (5, 3, 3)
        if self.actuation == "stress":
            return np.einsum("mij,kjl->kmil", F, S_k)
        # dG = Dexp(X)[S_k / mu] at X = sigma_a / mu (Daleckii-Krein: in X's eigenbasis, the
        # divided differences of exp); the shear stress's change mu J^-2/3 (F dG - (F:F dG)/3 F^-T)
        zero = np.zeros((len(F), 6)) if active is None else active
        _, lam, Q = self._strain_metric(zero)
        li, lj = lam[:, :, None], lam[:, None, :]
        gap = li - lj
        close = np.abs(gap) < 1e-9
        divided = np.where(
            close, np.exp((li + lj) / 2), np.exp(lj) * np.expm1(gap) / np.where(close, 1.0, gap)
        )
        in_basis = np.einsum("mai,kab,mbj->kmij", Q, S_k, Q)
        dG = np.einsum("mia,kmab,mjb->kmij", Q, divided[None] * in_basis, Q)  # mu dG per Pa
        FdG = np.einsum("mij,kmjl->kmil", F, dG)
        i1 = np.einsum("mij,kmij->km", F, FdG)
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        return J[None, :, None, None] ** (-2 / 3) * (FdG - (i1 / 3)[..., None, None] * FiT[None])

    def gradient(
        self,
        d: NDArray,
        f: NDArray | None = None,
        active: NDArray | None = None,
        hessian: bool = False,
    ) -> tuple[NDArray, sp.csr_matrix | None]:
        """d(E + E_a)/dd - f (3N,) N (``active`` (M, 6) Pa, Voigt) and, with ``hessian``, the
        exact Hessian (3N, 3N) N/m (the tangent stiffness; valid where every J > 0)."""
        m = self.model
        F, J = self.deformation(d)
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        strain = active is not None and self.actuation == "strain"
        G = self._strain_metric(active)[0] if strain else None
        FG = F if G is None else F @ G
        i1 = np.einsum("mij,mij->m", F, FG)
        a = J ** (-2 / 3)
        pressure = m.S.T @ (m.w_vol * (m.S @ np.log(J)))  # (M,) N m, dE/d(ln J_e)
        scale = (m.volumes * m.mu * a)[:, None, None]
        P = scale * (FG - (i1 / 3)[:, None, None] * FiT) + pressure[:, None, None] * FiT
        S_a = None if active is None or strain else tensors(active)
        if S_a is not None:
            P = P + m.volumes[:, None, None] * (F @ S_a)
        g = self._scatter(P)
        if f is not None:
            g = g - f
        if not hessian:
            return g, None
        # d(F^-T)/dF [ij, kl] = -F^-T_il F^-T_kj; d(F G)_ij/dF_kl = delta_ik G_lj; the
        # isochoric tangent (J^-2/3 mu V times)
        inv_t = np.einsum("mil,mkj->mijkl", FiT, FiT)
        outer = lambda A, B: np.einsum("mij,mkl->mijkl", A, B)  # noqa: E731
        if G is None:
            dFG = np.einsum("ik,jl->ijkl", np.eye(3), np.eye(3))[None]
        else:
            dFG = np.einsum("ik,mlj->mijkl", np.eye(3), G)
        c = i1[:, None, None, None, None]
        shear = (
            dFG - (2 / 3) * (outer(FG, FiT) + outer(FiT, FG))
            + (2 / 9) * c * outer(FiT, FiT) + (1 / 3) * c * inv_t
        )  # fmt: skip
        D = scale[..., None, None] * shear - pressure[:, None, None, None, None] * inv_t
        if S_a is not None:  # d(F S_a)_ij / dF_kl = delta_ik S_a,lj
            D = D + np.einsum("ik,mlj->mijkl", np.eye(3), m.volumes[:, None, None] * S_a)
        dFdu = _strain_map(m.grads)
        blocks = dFdu.transpose(0, 2, 1) @ (D.reshape(-1, 9, 9) @ dFdu)  # (M, 12, 12)
        H = assemble(blocks, m.tets, len(m.nodes))
        # the volumetric part's Gauss-Newton term: Gn^T diag(w) Gn, Gn = S d(ln J)/dd
        rows_ln = np.einsum("mij,maj->mai", FiT, m.grads).reshape(-1, 12)
        dln = sp.csr_matrix(
            (rows_ln.ravel(), m.dofs.ravel(), np.arange(0, rows_ln.size + 1, 12)),
            shape=(len(m.tets), m.n_dofs),
        )
        Gn = (m.S @ dln).tocsr()
        return g, (H + Gn.T @ sp.diags(m.w_vol) @ Gn).tocsr()


class NotConverged(RuntimeError):
    """The large-strain static solve did not reach its tolerance."""


def solve_static_large_strain(
    law: NeoHookeanANP,
    prescribed: NDArray,
    values: NDArray,
    f: NDArray | None = None,
    active: NDArray | None = None,
    start: NDArray | None = None,
    rtol: float = 1e-6,
    atol: float = 1e-9,
    max_iter: int = 30,
    factors: SymmetricFactors | None = None,
) -> tuple[NDArray, int]:
    """The equilibrium d (3N,) m of ``law`` under dead loads ``f`` (3N,) N and the
    actuation ``active`` (M, 6) Pa (Voigt) with d[prescribed] = ``values`` (m), by Newton's
    method with a backtracking line search on the energy from ``start`` (default: the rest;
    the prescribed values are taken first along the tangent, the step halved until no tet
    inverts); and the Newton iterations taken.

    Converged when |gradient| on the free DOFs <= rtol |f - f_a| + atol (N), f_a the active
    stress's forces at the start. NotConverged when it is not within ``max_iter`` iterations
    (load in smaller steps: the solve does not). The tangent may be indefinite far from
    equilibrium: ``factors`` (default: a new :class:`SymmetricFactors`, its analysis shared
    by the solve's iterations; pass one to share it across solves) factorises it."""
    m = law.model
    n = m.n_dofs
    pres = np.asarray(prescribed, dtype=np.int64)
    free = free_dofs(n, pres)
    force = np.zeros(n) if f is None else np.asarray(f, dtype=np.float64)
    d = np.zeros(n) if start is None else np.array(start, dtype=np.float64)
    jump = np.asarray(values, dtype=np.float64) - d[pres]
    factors = SymmetricFactors() if factors is None else factors
    if np.any(jump):  # take the prescribed values along the tangent at the start
        _, H = law.gradient(d, force, active, hessian=True)
        move = np.zeros(n)
        move[pres] = jump
        move[free] = -factors(H[free][:, free])(H[free][:, pres] @ jump)
        d = law.toward(d, d + move)
        d[pres] = values
        if np.any(law.deformation(d)[1] <= 0):
            raise NotConverged("the prescribed values invert tets: prescribe them in steps")
    # the scale of the loads: the dead loads and the actuation's forces at the start
    active_force = 0 if active is None else law.active_forces(d, active)
    tol = rtol * float(np.linalg.norm((force + active_force)[free])) + atol
    for it in range(max_iter):
        g, H = law.gradient(d, force, active, hessian=True)
        g_u = g[free]
        if np.linalg.norm(g_u) <= tol:
            return d, it
        step = np.zeros(n)
        step[free] = -factors(H[free][:, free])(g_u)
        slope = float(g_u @ step[free])
        if not slope < 0:  # an indefinite tangent: fall back on steepest descent
            step[free], slope = -g_u, -float(g_u @ g_u)
        e0, t = law.energy(d, force, active), 1.0
        while law.energy(d + t * step, force, active) > e0 + ARMIJO * t * slope and t > MIN_STEP:
            t /= 2
        d = d + t * step
    g, _ = law.gradient(d, force, active)
    if np.linalg.norm(g[free]) <= tol:
        return d, max_iter
    raise NotConverged(
        f"large-strain static solve: |gradient| {np.linalg.norm(g[free]):.3g} N after "
        f"{max_iter} Newton iterations (tolerance {tol:.3g} N); load in smaller steps"
    )
