"""Driven viscoelastic FEM dynamics of a tet mesh: the core of the ``simulate`` stage."""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
from threadpoolctl import threadpool_limits

from physanim.fem.boundary import SpringDrive
from physanim.fem.corotational import (
    CorotationalNewmark,
    local_displacements,
    rotations,
    strain_energy,
)
from physanim.fem.geometry import signed_volumes
from physanim.fem.interp import catmull_rom
from physanim.fem.materials import TetMaterials
from physanim.fem.model import FemModel, build_model
from physanim.fem.newmark import Newmark, State
from physanim.fem.numba_threads import faster_thread_count
from physanim.fem.parallel_spmv import ParallelCSR, SymmetricQuadraticForm
from physanim.fem.params import SimulateParams
from physanim.fem.statics import solve_static


class SimulationDiverged(RuntimeError):
    """The time integration produced NaN/Inf or an exploding energy."""


@dataclass
class SimResult:
    """Simulation output at the capture frame rate (T frames, N nodes, M tets).

    displacements (T, N, 3) float32, m; times (T,) s; kinetic, strain (T,) J;
    dissipated (T,) J, cumulative viscous dissipation since frame 0; max_von_mises (T,) Pa
    (elastic stress) and its 99th percentile over tets p99_von_mises (T,) Pa (a peak far
    above it is a stress hot spot); inverted_count (T,) number of inverted tets per frame;
    inverted_tets (K,) ids of tets inverted in any frame; dt: smallest substep used, s;
    n_substeps: most substeps in a frame; frame_substeps (T,) substeps that led to each frame
    (0 for the first); check_steps: steps the adaptive control computed and discarded (the
    coarse half of each step-doubling pair, rejected frames); frames_over_tolerance: frames
    whose error estimate stayed above the tolerance at the smallest step allowed;
    solver_threads (T,) numba threads used for each frame (all, or 1 when that was faster:
    cores busy with other processes);
    timings: seconds spent in 'assembly', 'factorization', 'stepping'.
    """

    displacements: np.ndarray
    times: np.ndarray
    kinetic: np.ndarray
    strain: np.ndarray
    dissipated: np.ndarray
    max_von_mises: np.ndarray
    p99_von_mises: np.ndarray
    inverted_count: np.ndarray
    inverted_tets: np.ndarray
    dt: float
    n_substeps: int
    timings: dict[str, float] = field(default_factory=dict)
    corot_iterations: np.ndarray | None = None
    frame_substeps: np.ndarray | None = None
    solver_threads: np.ndarray | None = None
    check_steps: int = 0
    frames_over_tolerance: int = 0


def hot_spot_ratio(result: SimResult, min_fraction: float = 0.05) -> float:
    """Worst peak / 99th-percentile von Mises ratio over the frames whose peak stress is at
    least ``min_fraction`` of the run's largest (a stress hot spot makes it large; frames at
    rest, whose stresses are round-off, do not count)."""
    vm, p99 = result.max_von_mises, result.p99_von_mises
    loaded = vm >= min_fraction * vm.max()
    if not loaded.any() or vm.max() <= 0:
        return 0.0
    return float(np.max(vm[loaded] / np.maximum(p99[loaded], 1e-300)))


def _node_index(name: str, idx: np.ndarray | None, n_nodes: int) -> np.ndarray:
    idx = np.zeros(0, np.int64) if idx is None else np.asarray(idx, dtype=np.int64).ravel()
    if idx.size and (idx.min() < 0 or idx.max() >= n_nodes):
        raise ValueError(
            f"{name} must index nodes in [0, {n_nodes}), got [{idx.min()}, {idx.max()}]"
        )
    if np.unique(idx).size != idx.size:
        raise ValueError(f"{name} contains repeated node indices")
    return idx


def _dofs(idx: np.ndarray) -> np.ndarray:
    return (3 * idx[:, None] + np.arange(3)).ravel()


@dataclass(frozen=True)
class _SpringForce:
    """Spring forces k_i u_i(t) (N), interpolated between frames like the prescribed motion."""

    springs: SpringDrive
    positions: np.ndarray  # (3S,) positions of the spring DOFs among the free DOFs
    dofs: np.ndarray  # (3S,) spring DOFs
    frame_dt: float
    n_free: int

    def _at(self, times: np.ndarray) -> np.ndarray:
        t = self.springs.targets.reshape(len(self.springs.targets), -1)
        return catmull_rom(t, self.frame_dt, times)[0] * np.repeat(self.springs.stiffness, 3)

    def free(self, times: np.ndarray) -> np.ndarray:
        """(len(times), n_free) forces on the free DOFs, N."""
        out = np.zeros((len(times), self.n_free))
        out[:, self.positions] = self._at(times)
        return out

    def full(self, time: float, n_dofs: int) -> np.ndarray:
        """(n_dofs,) forces at one time, N."""
        out = np.zeros(n_dofs)
        out[self.dofs] = self._at(np.array([time]))[0]
        return out


def _spring_force(springs: SpringDrive, free: np.ndarray, frame_dt: float) -> _SpringForce:
    dofs = springs.dofs()
    return _SpringForce(springs, np.searchsorted(free, dofs), dofs, frame_dt, len(free))


def simulate(
    nodes: np.ndarray,
    tets: np.ndarray,
    materials: TetMaterials,
    driven_idx: np.ndarray,
    driven_traj: np.ndarray,
    frame_dt: float,
    fixed_idx: np.ndarray | None = None,
    params: SimulateParams | None = None,
    progress: Callable[[int, int], None] | None = None,
    model: FemModel | None = None,
    springs: SpringDrive | None = None,
) -> SimResult:
    """Simulate the mesh with driven nodes following trajectories and fixed nodes held.

    nodes (N, 3) m; tets (M, 4) positively oriented; materials per tet; driven_idx (n_d,)
    node ids; driven_traj (T, n_d, 3) displacements from rest in m at frame times k frame_dt
    (s), interpolated between frames by Catmull-Rom splines; fixed_idx (n_f,) node ids held at
    zero displacement. ``springs`` optionally pulls free nodes towards moving targets (soft
    constraints, same frame times and interpolation). All other nodes are free. The first
    frame is the static equilibrium for driven_traj[0] and the springs' first targets.
    ``model`` may pass a prebuilt ``build_model`` result.

    On cores busy with other processes one thread can beat all of numba's: the run uses the
    faster (checked before factorising and every 30 frames; ``SimResult.solver_threads``).
    """
    most_threads = numba.get_num_threads()
    try:
        return _simulate(
            nodes, tets, materials, driven_idx, driven_traj, frame_dt, fixed_idx, params,
            progress, model, springs,
        )  # fmt: skip
    finally:
        numba.set_num_threads(most_threads)


def _simulate(
    nodes: np.ndarray,
    tets: np.ndarray,
    materials: TetMaterials,
    driven_idx: np.ndarray,
    driven_traj: np.ndarray,
    frame_dt: float,
    fixed_idx: np.ndarray | None = None,
    params: SimulateParams | None = None,
    progress: Callable[[int, int], None] | None = None,
    model: FemModel | None = None,
    springs: SpringDrive | None = None,
) -> SimResult:
    params = params or SimulateParams()
    t0 = time.perf_counter()
    model = model or build_model(nodes, tets, materials, params)
    t_asm = time.perf_counter() - t0
    n_nodes = len(model.nodes)
    driven_idx = _node_index("driven_idx", driven_idx, n_nodes)
    fixed_idx = _node_index("fixed_idx", fixed_idx, n_nodes)
    traj = np.asarray(driven_traj, dtype=np.float64)
    if traj.ndim != 3 or traj.shape[1:] != (driven_idx.size, 3) or len(traj) < 2:
        raise ValueError(
            f"driven_traj must have shape (T >= 2, {driven_idx.size}, 3), got {traj.shape}"
        )
    if not np.isfinite(traj).all():
        raise ValueError("driven_traj contains NaN or Inf")
    if np.intersect1d(driven_idx, fixed_idx).size:
        raise ValueError("driven_idx and fixed_idx share nodes; a node is driven or fixed")
    if not frame_dt > 0:
        raise ValueError(f"frame_dt must be > 0 s, got {frame_dt}")
    if springs is not None:
        if len(springs.targets) != len(traj):
            raise ValueError(
                f"springs have {len(springs.targets)} frames of targets, driven_traj {len(traj)}"
            )
        if np.intersect1d(springs.nodes, np.r_[driven_idx, fixed_idx]).size:
            raise ValueError("spring nodes must be free: not in driven_idx or fixed_idx")
        if params.corotational:
            raise ValueError("springs are not supported with the corotational option")

    n_max = max(1, math.ceil(frame_dt / params.dt - 1e-9))
    adaptive = params.stepping == "adaptive" and not params.corotational and n_max > 1
    # substeps per frame: 1, 2, 4, ... and n_max; adaptive frames pair level i and i + 1
    levels = sorted({min(2**i, n_max) for i in range(n_max.bit_length() + 1)})
    if not adaptive:
        levels = [n_max]
    n_frames = len(traj)
    pres = np.concatenate([_dofs(driven_idx), _dofs(fixed_idx)])
    n_fix = 3 * fixed_idx.size
    values = traj.reshape(n_frames, -1)

    most_threads = numba.get_num_threads()
    probe_op, probe = ParallelCSR(model.K), np.ones(model.n_dofs)
    faster_thread_count(lambda: probe_op @ probe, most_threads, repeats=5)
    t0 = time.perf_counter()
    stiffness, split = model.K, model.split
    if springs is not None:
        k_springs = springs.matrix(model.n_dofs)
        stiffness = (stiffness + k_springs).tocsr()
        if split is not None:
            split = ((split[0] + k_springs).tocsr(), split[1], split[2])
    h0 = frame_dt / levels[0]
    with threadpool_limits(limits=numba.get_num_threads(), user_api="blas"):  # CHOLMOD's too
        if params.corotational:
            integ: Newmark = CorotationalNewmark(
                model, h0, pres, params.solver, params.corot_rtol, params.corot_max_iter
            )
        else:
            integ = Newmark(
                stiffness, model.M, model.C, h0, pres, params.solver, split, params.precision
            )
    integrators = _IntegratorCache(integ, levels[0], frame_dt, params.factor_cache)
    t_fac = time.perf_counter() - t0
    force = _spring_force(springs, integ.free, frame_dt) if springs is not None else None

    def prescribed(times: np.ndarray):
        d, v, a = catmull_rom(values, frame_dt, times)
        pad = np.zeros((len(times), n_fix))
        return (np.hstack([x, pad]) for x in (d, v, a))

    state = State.rest(model.n_dofs)
    d_c, v_c, a_c = (x[0] for x in prescribed(np.zeros(1)))
    f0 = None if force is None else force.full(0.0, model.n_dofs)
    loaded = f0 is not None and bool(np.any(f0))
    if np.any(d_c) or loaded:
        state.d[:] = solve_static(stiffness, pres, d_c, f0, solver=params.solver)
    state.v[pres], state.a[pres] = v_c, a_c
    if np.any(v_c) or np.any(a_c) or loaded:
        integ.initial_acceleration(state, f0)

    k_diag = model.K.diagonal()[pres]
    e_drive = 0.5 * float(((np.hstack([values, np.zeros((n_frames, n_fix))]) ** 2) @ k_diag).max())
    if springs is not None:
        e_springs = 0.5 * ((springs.targets**2).sum(axis=2) @ springs.stiffness).max()
        e_drive = max(e_drive, float(e_springs))

    out = np.zeros((n_frames, n_nodes, 3), dtype=np.float32)
    kin, pot, diss, vm, vm99 = (np.zeros(n_frames) for _ in range(5))
    inv_count = np.zeros(n_frames, dtype=np.int64)
    inverted: set[int] = set()

    kinetic_form = SymmetricQuadraticForm(model.M)
    strain_form = None if params.corotational else SymmetricQuadraticForm(model.K)

    def record(k: int) -> None:
        d = state.d
        out[k] = d.reshape(-1, 3)
        kin[k] = 0.5 * kinetic_form(state.v)
        if params.corotational:
            u_loc = local_displacements(model, d, rotations(model, d))
            pot[k] = strain_energy(model, u_loc)
        else:
            u_loc = d[model.dofs]
            pot[k] = 0.5 * strain_form(d)
        stress = model.von_mises(u_loc)
        vm[k], vm99[k] = stress.max(), np.percentile(stress, 99)
        bad = np.flatnonzero(signed_volumes(model.nodes + d.reshape(-1, 3), model.tets) <= 0)
        inv_count[k] = bad.size
        inverted.update(bad.tolist())

    record(0)
    e_max = kin[0] + pot[0]
    t0 = time.perf_counter()
    dissipated = 0.0
    tol = params.error_tol_mm * 1e-3
    level, rejected, over = 0, 0, 0
    substeps = np.zeros(n_frames, dtype=np.int64)

    def advance(k: int, n_sub: int, heat_too: bool = True) -> float:
        """Steps from frame k - 1 to frame k in n_sub substeps; returns the dissipation, J
        (0 unless ``heat_too``)."""
        integ, h = integrators.get(n_sub), frame_dt / n_sub
        times = (k - 1) * frame_dt + h * np.arange(1, n_sub + 1)
        dd, vv, aa = prescribed(times)
        ff = None if force is None else force.free(times)
        heat = 0.0
        for j in range(n_sub):
            d_old = state.d.copy()
            integ.step(state, dd[j], vv[j], aa[j], None if ff is None else ff[j])
            if not np.isfinite(state.d).all():
                node = int(np.abs(d_old).reshape(-1, 3).max(axis=1).argmax())
                raise SimulationDiverged(
                    f"frame {k}, substep {j + 1} of {n_sub} (t = {times[j]:.6g} s): "
                    f"displacement became NaN/Inf; largest displacement before it "
                    f"{np.abs(d_old).max():.3e} m at node {node}; reduce params.dt or "
                    "check materials"
                )
            if heat_too:
                heat += integ.dissipation(state.d - d_old)
        return heat

    threads = np.zeros(n_frames, dtype=np.int64)
    probe = np.ones(len(integ.free))
    # numpy's BLAS threads, once woken by a per-frame product, spin on the cores that the
    # solver's threads need (measured 30 % slower steps on two cores): keep BLAS on one
    with threadpool_limits(limits=1, user_api="blas"):
        for k in range(1, n_frames):
            if k % 30 == 1:  # other processes come and go: re-check every 30 frames
                solve = integrators.get(levels[level]).solve
                faster_thread_count(lambda: solve(probe), most_threads)  # noqa: B023
            threads[k] = numba.get_num_threads()
            if adaptive:
                # step doubling: the frame in n and in 2n substeps from the same state; the
                # finer result is kept, its error estimated as |d_2n - d_n| / (r^2 - 1)
                saved = (state.d.copy(), state.v.copy(), state.a.copy())
                while True:
                    coarse, fine = levels[level], levels[level + 1]
                    advance(k, coarse, heat_too=False)
                    d_coarse = state.d.copy()
                    state.d[:], state.v[:], state.a[:] = saved
                    heat = advance(k, fine)
                    ratio = fine / coarse
                    error = float(np.abs(state.d - d_coarse).max()) / (ratio**2 - 1)
                    if error <= tol or level + 2 == len(levels):
                        over += error > tol
                        break
                    state.d[:], state.v[:], state.a[:] = saved
                    rejected += coarse + fine
                    level += 1
                # local error ~ dt^3: next frame a coarser pair when it would stay in tol / 2
                if level > 0 and error * (coarse / levels[level - 1]) ** 3 < tol / 2:
                    level -= 1
                substeps[k] = fine
                rejected += coarse
            else:
                heat = advance(k, levels[0])
                substeps[k] = levels[0]
            dissipated += heat
            record(k)
            diss[k] = dissipated
            energy = kin[k] + pot[k]
            if energy > params.energy_blowup_factor * max(e_max, e_drive) and energy > 0:
                node = int(np.linalg.norm(out[k], axis=1).argmax())
                raise SimulationDiverged(
                    f"frame {k} (t = {k * frame_dt:.6g} s): energy "
                    f"{energy:.3e} J exceeds {params.energy_blowup_factor:g} x "
                    f"{max(e_max, e_drive):.3e} J; largest displacement "
                    f"{np.linalg.norm(out[k], axis=1).max():.3e} m at node {node}"
                )
            e_max = max(e_max, energy)
            if progress is not None:
                progress(k, n_frames - 1)
    t_step = time.perf_counter() - t0
    iters = getattr(integ, "iterations", None)
    return SimResult(
        displacements=out,
        times=frame_dt * np.arange(n_frames),
        kinetic=kin,
        strain=pot,
        dissipated=diss,
        max_von_mises=vm,
        p99_von_mises=vm99,
        inverted_count=inv_count,
        inverted_tets=np.array(sorted(inverted), dtype=np.int64),
        dt=frame_dt / substeps.max(initial=1),
        n_substeps=int(substeps.max(initial=1)),
        timings={
            "assembly": t_asm,
            "factorization": t_fac + integrators.seconds,
            "stepping": t_step - integrators.seconds,
        },
        corot_iterations=None if iters is None else np.asarray(iters),
        frame_substeps=substeps,
        solver_threads=threads,
        check_steps=rejected,
        frames_over_tolerance=over,
    )


class _IntegratorCache:
    """Newmark integrators by substeps per frame; the least recently used beyond ``size``
    is dropped (its factor freed). ``seconds``: time spent factorising after the first."""

    def __init__(self, first: Newmark, n_sub: int, frame_dt: float, size: int) -> None:
        self._items: OrderedDict[int, Newmark] = OrderedDict({n_sub: first})
        self._template, self._frame_dt, self._size = first, frame_dt, size
        self.seconds = 0.0

    def get(self, n_sub: int) -> Newmark:
        if n_sub in self._items:
            self._items.move_to_end(n_sub)
            return self._items[n_sub]
        t0 = time.perf_counter()
        integ = self._template.with_dt(self._frame_dt / n_sub)
        self.seconds += time.perf_counter() - t0
        self._items[n_sub] = integ
        while len(self._items) > self._size:
            self._items.popitem(last=False)
        return integ
