"""Reduced (snapshot POD) model of the driven viscoelastic FEM, for previews of material edits.

A full run of one material (the *basis run*) gives snapshots of the free DOFs' displacements
at the capture frames; their SVD gives an orthonormal basis Phi (n_u, r) of the r leading
modes (``pod_basis``). Another material on the same mesh, drive and boundary conditions is
then run in those coordinates, d_u = Phi q: its K (with the drive's springs), M and C are
projected once (Galerkin, ``project``: sparse times dense, then r x r), and Newmark (beta
1/4, gamma 1/2, the prescribed DOFs' motion and the spring forces exactly as in the full run,
:class:`~physanim.fem.boundary.BoundaryConditions`) steps the r unknowns (``simulate_reduced``).
When the basis spans every substep of a full run, the reduced run reproduces it to round-off;
otherwise its error against the full run is measured (``displacement_error``) or estimated
from the full model's residual (``residual_estimate``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numpy.typing import NDArray

from physanim.fem.actuation import Actuation
from physanim.fem.boundary import BoundaryConditions, FrameForce
from physanim.fem.interp import catmull_rom_position
from physanim.fem.linsolve import factorize
from physanim.fem.materials import TetMaterials
from physanim.fem.model import FemModel
from physanim.fem.monitors import InversionMonitor, StressMonitor
from physanim.fem.newmark import State
from physanim.fem.numba_threads import faster_thread_count, keeps_thread_count
from physanim.fem.problem import applied_load
from physanim.fem.simulate import SimResult
from physanim.fem.statics import free_dofs


@dataclass(frozen=True)
class PodBasis:
    """``phi`` (n_u, r) orthonormal columns over the free DOFs ``free`` (n_u,);
    ``singular_values`` (s,) of the whole snapshot matrix (m), largest first."""

    phi: NDArray
    free: NDArray
    singular_values: NDArray

    @property
    def size(self) -> int:
        """Number of modes r."""
        return int(self.phi.shape[1])

    @property
    def energy(self) -> float:
        """Share of the snapshots' squared norm (sum of s^2) the r modes capture, in [0, 1]."""
        s2 = self.singular_values**2
        return float(s2[: self.size].sum() / s2.sum()) if s2.sum() > 0 else 1.0


def pod_basis(
    snapshots: NDArray,
    free: NDArray,
    energy: float = 0.999999,
    max_modes: int = 150,
    extra: NDArray | None = None,
) -> PodBasis:
    """The fewest leading left singular vectors of the free DOFs' snapshots that capture
    ``energy`` of their squared norm, at most ``max_modes``.

    snapshots (T, n_dofs) or (T, N, 3) displacements, m; free (n_u,) DOF ids; ``extra``
    (n_u, k) more snapshot columns over the free DOFs, m (e.g. ``material_sensitivities``).
    """
    x = np.asarray(snapshots, dtype=np.float64).reshape(len(snapshots), -1)[:, free].T
    if extra is not None:
        x = np.hstack([x, extra])
    u, s, _ = np.linalg.svd(x, full_matrices=False)
    if not s.size or s[0] == 0:
        raise ValueError("pod_basis: the snapshots are all zero; nothing moves in the basis run")
    captured = np.cumsum(s**2) / np.sum(s**2)
    rank = int(np.sum(s > s[0] * 1e-12))  # drop directions that are round-off
    r = min(int(np.searchsorted(captured, energy - 1e-15)) + 1, max_modes, rank)
    return PodBasis(u[:, :r].copy(), np.asarray(free, dtype=np.int64), s)


@dataclass(frozen=True)
class ReducedSystem:
    """The Galerkin projection of K (with springs), M, C onto a basis: ``k``, ``m``, ``c``
    (r, r) N/m, kg, N s/m; their couplings to the prescribed DOFs that move ``moving``
    (n_m,) (indices into the prescribed DOFs): ``bk``, ``bm``, ``bc`` (r, n_m) = Phi^T X_um;
    ``k_mm``, ``m_mm``, ``c_mm`` (n_m, n_m) sparse, the blocks among those DOFs (energies)."""

    basis: PodBasis
    k: NDArray
    m: NDArray
    c: NDArray
    bk: NDArray
    bm: NDArray
    bc: NDArray
    k_mm: sp.csr_matrix
    m_mm: sp.csr_matrix
    c_mm: sp.csr_matrix
    moving: NDArray


def project(
    stiffness: sp.spmatrix,
    mass: sp.spmatrix,
    damping: sp.spmatrix,
    basis: PodBasis,
    prescribed: NDArray,
    moving: NDArray,
) -> ReducedSystem:
    """Project (n, n) ``stiffness`` (N/m, springs included), ``mass`` (kg) and ``damping``
    (N s/m) onto ``basis``; ``prescribed`` (n_c,) DOF ids of which ``moving`` (n_m,) (indices
    into ``prescribed``) ever leave rest."""
    n = stiffness.shape[0]
    lifted = np.zeros((n, basis.size))
    lifted[basis.free] = basis.phi
    cols = np.asarray(prescribed)[moving]
    reduced, coupling, blocks = [], [], []
    for x in (stiffness, mass, damping):
        x = sp.csr_matrix(x)
        xp = x @ lifted  # (n, r)
        xr = lifted.T @ xp
        reduced.append(0.5 * (xr + xr.T))
        coupling.append(xp[cols].T.copy())  # X symmetric: (X P)[c] = (Phi^T X_uc)^T
        blocks.append(x[cols][:, cols].tocsr())
    return ReducedSystem(basis, *reduced, *coupling, *blocks, moving)


def _cholesky(a: NDArray) -> Callable[[NDArray], NDArray]:
    factor = sla.cho_factor(a)
    return lambda b: sla.cho_solve(factor, b)


@dataclass(frozen=True)
class ReducedRun:
    """A reduced run: ``result`` as the full run reports it, and the reduced coordinates at
    the frames, ``q``, ``qd``, ``qdd`` (T, r) in m, m/s, m/s^2 (d_u = Phi q)."""

    result: SimResult
    q: NDArray
    qd: NDArray
    qdd: NDArray


@keeps_thread_count
def simulate_reduced(
    model: FemModel,
    bc: BoundaryConditions,
    basis: PodBasis,
    substeps: NDArray,
    progress: Callable[[int, int], None] | None = None,
    actuation: Actuation | None = None,
) -> ReducedRun:
    """The run of ``model`` under ``bc`` (and ``actuation``, if any) in the coordinates of
    ``basis``, with ``substeps`` (T,) Newmark substeps leading to each frame (entry 0 unused;
    e.g. the basis run's ``frame_substeps``, so that the time discretisation is the same).

    The first frame is the reduced static equilibrium. The run's :class:`SimResult` holds what
    the full run reports (displacements reconstructed on every node, energies, stresses and
    inverted tets from them; ``solver_threads`` 0); its ``timings``: 'projection',
    'stepping' and 'monitors', s.
    """
    substeps = np.asarray(substeps, dtype=np.int64)
    if len(substeps) != bc.n_frames or np.any(substeps[1:] < 1):
        raise ValueError(
            f"substeps must be (T,) = ({bc.n_frames},) with entries >= 1 after the first"
        )
    t0 = time.perf_counter()
    pres = bc.prescribed_dofs
    free = free_dofs(model.n_dofs, pres)
    if not np.array_equal(free, basis.free):
        raise ValueError("the basis was built for other free DOFs than these conditions")
    stiffness, _ = bc.with_springs(model.K, None)
    # prescribed DOFs that never leave rest add nothing: keep the others only
    n_driven = bc.values.shape[1]
    moving = np.flatnonzero(np.any(bc.values != 0, axis=0))
    moving = moving[moving < n_driven]
    red = project(stiffness, model.M, model.C, basis, pres, moving)
    force = applied_load(bc, actuation, model, free)
    phi_force = None if force is None else basis.phi[force.positions]
    t_proj = time.perf_counter() - t0

    t0 = time.perf_counter()
    frame_dt, n_frames = bc.frame_dt, bc.n_frames
    # every substep's time and step size, and the loads there, at once
    frame = np.repeat(np.arange(1, n_frames), substeps[1:])  # (S,) frame each step leads to
    h = frame_dt / substeps[frame]
    first = np.r_[0, np.cumsum(substeps[1:])[:-1]]  # index of each frame's first step
    times = (frame - 1) * frame_dt + h * (np.arange(len(frame)) - first[frame - 1] + 1)
    d_m, v_m, a_m = (x[:, moving] for x in bc.prescribed(np.r_[0.0, times]))
    load = _projected_load(force, phi_force, np.r_[0.0, times])
    load -= d_m @ red.bk.T + v_m @ red.bc.T + a_m @ red.bm.T  # (S + 1, r), N
    q = _cholesky(red.k)(load[0] + red.bc @ v_m[0] + red.bm @ a_m[0])  # static: K q = f
    qd = np.zeros(basis.size)
    qdd = _cholesky(red.m)(load[0] - red.k @ q)
    steps = np.zeros((len(frame) + 1, basis.size))
    steps[0] = q
    qs = np.zeros((n_frames, basis.size))
    qds, qdds = np.zeros_like(qs), np.zeros_like(qs)
    qs[0], qds[0], qdds[0] = q, qd, qdd
    solvers: dict[float, Callable[[NDArray], NDArray]] = {}
    for s, step in enumerate(h):
        if step not in solvers:
            solvers[step] = _cholesky(red.k + (4 / step**2) * red.m + (2 / step) * red.c)
        rhs = red.m @ ((4 / step**2) * q + (4 / step) * qd + qdd) + red.c @ ((2 / step) * q + qd)
        q_new = solvers[step](rhs + load[s + 1])
        qdd_new = (4 / step**2) * (q_new - q) - (4 / step) * qd - qdd
        qd = qd + 0.5 * step * (qdd + qdd_new)
        q, qdd = q_new, qdd_new
        steps[s + 1] = q
        k = frame[s]
        if s + 1 == len(h) or frame[s + 1] != k:
            qs[k], qds[k], qdds[k] = q, qd, qdd
            if progress is not None:
                progress(k, n_frames - 1)
    # viscous dissipation of each step: delta^T C delta / h over free and moving DOFs
    dq, dc = np.diff(steps, axis=0), np.diff(d_m, axis=0)
    work = np.einsum("si,ij,sj->s", dq, red.c, dq) + 2 * np.einsum("si,im,sm->s", dq, red.bc, dc)
    work += np.einsum("sm,sm->s", dc, (red.c_mm @ dc.T).T)
    heat = np.zeros(n_frames)
    np.add.at(heat, frame, work / h)
    t_step = time.perf_counter() - t0

    t0 = time.perf_counter()
    k_el = red.k
    if bc.springs is not None:  # strain energy: the tissue's alone
        phi_springs = basis.phi[np.searchsorted(free, bc.springs.dofs())]
        k_el = red.k - (phi_springs.T * np.repeat(bc.springs.stiffness, 3)) @ phi_springs
    out, kinetic, strain, stress, inversion = _monitored(model, bc, red, k_el, (qs, qds))
    t_mon = time.perf_counter() - t0
    most = int(substeps[1:].max(initial=1))
    result = SimResult(
        displacements=out,
        times=frame_dt * np.arange(n_frames),
        kinetic=kinetic,
        strain=strain,
        dissipated=np.cumsum(heat),
        max_von_mises=stress.max,
        p99_von_mises=stress.p99,
        inverted_count=inversion.count,
        inverted_tets=inversion.tets(),
        dt=frame_dt / most,
        n_substeps=most,
        timings={"projection": t_proj, "stepping": t_step, "monitors": t_mon},
        frame_substeps=np.r_[0, substeps[1:]],
        solver_threads=np.zeros(n_frames, dtype=np.int64),  # no sparse solver ran
    )
    return ReducedRun(result, qs, qds, qdds)


def _projected_load(force: FrameForce | None, phi_force: NDArray | None, times: NDArray):
    """(len(times), r) projected applied forces Phi^T f_u(t) (springs, actuation), N."""
    if force is None or phi_force is None:
        return 0.0 * times[:, None]
    # the spline is linear in its values: project the frames' forces, then interpolate
    # (r columns, not the free DOFs': 0.8 s less on a 2 mm demo mesh)
    return catmull_rom_position(force.values @ phi_force, force.frame_dt, times)


def _monitored(
    model: FemModel,
    bc: BoundaryConditions,
    red: ReducedSystem,
    k_el: NDArray,
    run: tuple[NDArray, NDArray],
) -> tuple[NDArray, NDArray, NDArray, StressMonitor, InversionMonitor]:
    """Full displacements (T, N, 3) float32 m from the reduced ones ``run`` = (q, qd) (T, r),
    kinetic and strain energy (T,) J (in reduced coordinates; ``k_el`` (r, r) the projected
    stiffness without springs), and the full run's stress and inversion monitors."""
    q, qd = run
    n_frames, basis, pres = len(q), red.basis, bc.prescribed_dofs
    d_c, v_c, _ = bc.prescribed(bc.frame_dt * np.arange(n_frames))
    d_m, v_m = d_c[:, red.moving], v_c[:, red.moving]

    def energy(x: NDArray, xr: NDArray, b: NDArray, x_mm: sp.csr_matrix, c: NDArray):
        inner = np.einsum("ti,ij,tj->t", x, xr, x) + 2 * np.einsum("ti,im,tm->t", x, b, c)
        return 0.5 * (inner + np.einsum("tm,tm->t", c, (x_mm @ c.T).T))

    kinetic = energy(qd, red.m, red.bm, red.m_mm, v_m)
    strain = energy(q, k_el, red.bk, red.k_mm, d_m)
    monitors = (StressMonitor(model, n_frames), InversionMonitor(model, n_frames))
    out = np.zeros((n_frames, len(model.nodes), 3), dtype=np.float32)
    state = State.rest(model.n_dofs)
    probe = state.d[model.dofs]
    faster_thread_count(lambda: model.von_mises(probe), numba.get_num_threads())
    d_free = q @ basis.phi.T  # (T, n_u), one product
    for k in range(n_frames):
        state.d[basis.free], state.d[pres] = d_free[k], d_c[k]
        out[k] = state.d.reshape(-1, 3)
        u_elem = state.d[model.dofs]
        for monitor in monitors:
            monitor.record(k, state, u_elem)
    return out, kinetic, strain, *monitors


def material_sensitivities(
    model: FemModel,
    bc: BoundaryConditions,
    snapshots: NDArray,
    times: NDArray,
    labels: NDArray,
    rebuild: Callable[[TetMaterials], FemModel],
    materials: TetMaterials,
    n_modes: int = 20,
    solver: str = "auto",
) -> NDArray:
    """Snapshots (n_u, 3 L n_modes) of how the run's displacements change when one material
    region's stiffness or viscosity changes, to enrich a POD basis for material edits.

    For each of the L labels in ``labels`` (M,) (a region of the ``materials`` the run of
    ``model`` used), Young's modulus E and viscosity eta doubled on that region alone give
    K_j and C_j (``rebuild``: materials -> model of the same mesh). The first-order change of
    a quasi-static response d to log E_j is s_j = -K_uu^-1 (K_j d)_u, to log eta_j
    -K_uu^-1 (C_j v)_u, and the second-order one to log E_j lies along K_uu^-1 (K_j)_uu s_j:
    taken for the ``n_modes`` leading modes of the displacement snapshots (T, N, 3) m at
    ``times`` (T,) s and of their velocities, scaled by their singular values (so the columns
    weigh as the run's own snapshots do). The second order is for a run driven by forces (an
    actuation), whose response scales with the compliance: on the demo, models 1-3 previewed
    in the uniform run's basis were 4.0 % off with the first order alone, 0.57 % with it. One
    factorisation of K_uu (springs included), 3 L n_modes solves.
    """
    x = np.asarray(snapshots, dtype=np.float64).reshape(len(snapshots), -1)
    modes = []
    for y in (x, np.gradient(x, np.asarray(times), axis=0)):
        u, s, _ = np.linalg.svd(y.T, full_matrices=False)
        modes.append(u[:, :n_modes] * s[:n_modes])
    stiffness, _ = bc.with_springs(model.K, None)
    free = free_dofs(model.n_dofs, bc.prescribed_dofs)
    solve = factorize(sp.csr_matrix(stiffness)[free][:, free].tocsc(), solver)
    out = []
    for label in np.unique(labels):
        on = labels == label
        doubled = dataclasses.replace(
            materials,
            E=np.where(on, 2 * materials.E, materials.E),
            eta=np.where(on, 2 * materials.eta, materials.eta),
        )
        edited = rebuild(doubled)
        stiffer = sp.csr_matrix(edited.K - model.K)
        first = -solve(np.asarray((stiffer @ modes[0])[free]))
        out += [first, solve(np.asarray(stiffer[free][:, free] @ first))]
        out.append(-solve(np.asarray(((edited.C - model.C) @ modes[1])[free])))
    return np.hstack(out)


def displacement_error(
    displacements: NDArray, reference: NDArray, nodes: NDArray | None = None
) -> dict[str, float]:
    """Error of displacements (T, N, 3) m against a reference run (T, N, 3) m over ``nodes``
    (default all): ``peak`` = max over frames and nodes of |u - u_ref| / max |u_ref|, and
    ``rms`` = RMS |u - u_ref| / RMS |u_ref| (dimensionless)."""
    sel = slice(None) if nodes is None else np.asarray(nodes)
    u = np.asarray(displacements, dtype=np.float64)[:, sel]
    ref = np.asarray(reference, dtype=np.float64)[:, sel]
    diff = np.linalg.norm(u - ref, axis=2)
    size = np.linalg.norm(ref, axis=2)
    peak, rms = float(size.max()), float(np.sqrt(np.mean(size**2)))
    return {
        "peak": float(diff.max()) / peak if peak > 0 else 0.0,
        "rms": float(np.sqrt(np.mean(diff**2))) / rms if rms > 0 else 0.0,
    }


def region_errors(
    displacements: NDArray, reference: NDArray, tets: NDArray, labels: NDArray, names: list[str]
) -> dict[str, float]:
    """Per region: max over frames and the nodes of its tets (labels (M,) index ``names``) of
    |u - u_ref|, over the whole run's max |u_ref| (so the regions' figures compare);
    displacements and reference (T, N, 3) m."""
    diff = np.linalg.norm(np.asarray(displacements, np.float64) - reference, axis=2).max(axis=0)
    peak = float(np.linalg.norm(np.asarray(reference, np.float64), axis=2).max())
    out = {}
    for j, name in enumerate(names):
        nodes = np.unique(np.asarray(tets)[np.asarray(labels) == j])
        if nodes.size:
            out[name] = float(diff[nodes].max()) / peak if peak > 0 else 0.0
    return out


def residual_estimate(
    model: FemModel,
    bc: BoundaryConditions,
    basis: PodBasis,
    run: ReducedRun,
    solver: str = "auto",
    actuation: Actuation | None = None,
) -> NDArray:
    """Estimated error (T, N, 3) m of a reduced run, without the full run: K_uu^-1 r_u in
    every frame, r_u = f_u - (M a + C v + K d)_u the full model's residual of the reduced
    trajectory (K with the springs, f_u the springs' and the ``actuation``'s forces). The
    error e obeys M e'' + C e' + K e = r exactly; the estimate leaves out inertia and
    viscosity of e itself (the tissue is strongly damped).
    One factorisation of K_uu."""
    stiffness, _ = bc.with_springs(model.K, None)
    pres, free = bc.prescribed_dofs, basis.free
    n_frames = len(run.q)
    times = bc.frame_dt * np.arange(n_frames)
    full = []
    for coords, given in zip((run.q, run.qd, run.qdd), bc.prescribed(times), strict=True):
        x = np.zeros((n_frames, model.n_dofs))
        x[:, free], x[:, pres] = coords @ basis.phi.T, given
        full.append(x)
    rows = lambda a: sp.csr_matrix(a)[free]  # noqa: E731
    r = -(rows(stiffness) @ full[0].T + rows(model.C) @ full[1].T + rows(model.M) @ full[2].T)
    force = applied_load(bc, actuation, model, free)
    if force is not None:
        r[force.positions] += force.at(times).T
    solve = factorize(sp.csr_matrix(stiffness)[free][:, free].tocsc(), solver)
    err = np.zeros((n_frames, model.n_dofs))
    err[:, free] = solve(r).T
    return err.reshape(n_frames, -1, 3)
