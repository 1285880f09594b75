"""Driven viscoelastic FEM dynamics of a tet mesh: the core of the ``simulate`` stage.

``simulate`` composes the parts: the model (:func:`build_model`: element formulation and
constitutive law), the boundary conditions (:mod:`.boundary`), the kinematics
(:mod:`.kinematics`), the integrator (adaptive Newmark, :mod:`.stepping`) and the per-frame
monitors (:mod:`.monitors`).
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
from threadpoolctl import threadpool_limits

from physanim.fem.boundary import SpringDrive
from physanim.fem.kinematics import kinematics
from physanim.fem.materials import TetMaterials
from physanim.fem.model import FemModel, build_model
from physanim.fem.monitors import EnergyMonitor, InversionMonitor, StressMonitor
from physanim.fem.numba_threads import ThreadTrials, faster_thread_count, keeps_thread_count
from physanim.fem.parallel_spmv import ParallelCSR
from physanim.fem.params import SimulateParams
from physanim.fem.problem import FemProblem
from physanim.fem.stepping import FrameStepper, IntegratorCache, initial_state, substep_levels


@dataclass(frozen=True)
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
    cores busy with other processes; one frame in 30 tries the other count);
    timings: seconds spent in 'assembly', 'factorization', 'stepping'; solver: the Newmark
    matrix's solver ('pardiso', 'cholmod', 'superlu', ...); factor_entries: its factor's L
    (0 where not counted).
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
    solver: str = ""
    factor_entries: int = 0


def frames_per_thread_count(solver_threads: np.ndarray) -> dict[str, int]:
    """{numba threads: frames stepped on them} of a run's ``solver_threads`` (T,), most used
    first (frame 0, the initial state, is not stepped)."""
    counts = collections.Counter(int(t) for t in solver_threads[1:])
    return {str(n): k for n, k in counts.most_common()}


def hot_spot_ratio(result: SimResult, min_fraction: float = 0.05) -> float:
    """Worst peak / 99th-percentile von Mises ratio over the frames whose peak stress is at
    least ``min_fraction`` of the run's largest (a stress hot spot makes it large; frames at
    rest, whose stresses are round-off, do not count)."""
    vm, p99 = result.max_von_mises, result.p99_von_mises
    loaded = vm >= min_fraction * vm.max()
    if not loaded.any() or vm.max() <= 0:
        return 0.0
    return float(np.max(vm[loaded] / np.maximum(p99[loaded], 1e-300)))


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
    constraints, same frame times and interpolation). All other nodes are free. The arrays
    form a :class:`FemProblem`, solved by :func:`simulate_problem`.
    """
    problem = FemProblem.driven(
        nodes, tets, materials, driven_idx, driven_traj, frame_dt, fixed_idx, springs
    )
    return simulate_problem(problem, params, progress, model)


@keeps_thread_count
def simulate_problem(
    problem: FemProblem,
    params: SimulateParams | None = None,
    progress: Callable[[int, int], None] | None = None,
    model: FemModel | None = None,
) -> SimResult:
    """Solve ``problem`` at its frame times. The first frame is the static equilibrium for
    the first prescribed displacements, the springs' first targets and the first actuation.
    ``model`` may pass a prebuilt ``build_model`` result (e.g. another element formulation:
    ``build_model(..., element=...)``); by default the model is ``params``' law and element.

    On cores busy with other processes one thread can beat all of numba's: the run uses the
    faster (checked before factorising, then on one frame in 30: ``SimResult.solver_threads``).
    """
    params = params or SimulateParams()
    t0 = time.perf_counter()
    model = model or build_model(problem.nodes, problem.tets, problem.materials, params)
    t_asm = time.perf_counter() - t0
    n_nodes = len(model.nodes)
    bc, frame_dt = problem.conditions, problem.frame_dt
    kin = kinematics(model, params)
    if bc.springs is not None and not kin.springs:
        raise ValueError("springs are not supported with the corotational option")
    if problem.actuation is not None and not kin.springs:
        raise ValueError("actuation is not supported with the corotational option")
    levels = substep_levels(frame_dt, params, kin.adaptive)
    n_frames, pres = bc.n_frames, bc.prescribed_dofs

    most_threads = numba.get_num_threads()
    probe_op, probe = ParallelCSR(model.K_el), np.ones(model.n_dofs)
    faster_thread_count(lambda: probe_op @ probe, most_threads, repeats=5)
    t0 = time.perf_counter()
    # with the split the integrator forms K only if its solver needs it
    stiffness, split = bc.with_springs(None if model.split else model.K, model.split)
    with threadpool_limits(limits=numba.get_num_threads(), user_api="blas"):  # CHOLMOD's too
        integ = kin.integrator(stiffness, split, frame_dt / levels[0], pres)
    integrators = IntegratorCache(integ, levels[0], frame_dt, params.factor_cache)
    t_fac = time.perf_counter() - t0
    force = problem.load(model, integ.free)
    stepper = FrameStepper(
        integrators, levels, bc, force, params.error_tol_mm * 1e-3, params.error_estimate
    )

    state = initial_state(integ, bc, force, params.solver)

    out = np.zeros((n_frames, n_nodes, 3), dtype=np.float32)
    energy = EnergyMonitor(
        model, kin, n_frames, problem.drive_energy(model), params.energy_blowup_factor
    )
    monitors = (energy, StressMonitor(model, n_frames), InversionMonitor(model, n_frames))

    def record(k: int, heat: float) -> None:
        out[k] = state.d.reshape(-1, 3)
        u_elem = kin.element_displacements(state.d)
        for monitor in monitors:
            monitor.record(k, state, u_elem)
        energy.check(k, heat, frame_dt, out[k])

    record(0, 0.0)
    t0 = time.perf_counter()
    threads = np.zeros(n_frames, dtype=np.int64)
    trials = ThreadTrials(most_threads)
    # numpy's BLAS threads, once woken by a per-frame product, spin on the cores that the
    # solver's threads need (measured 30 % slower steps on two cores): keep BLAS on one
    with threadpool_limits(limits=1, user_api="blas"):
        k, shown = 1, 0
        while k < n_frames:
            threads[k] = trials.start(k)
            t_frame = time.perf_counter()
            heat = stepper.frame(state, k)
            trials.finish(time.perf_counter() - t_frame, stepper.solves)
            if stepper.redo is not None:  # a frame over the tolerance: from it again, finer
                k = stepper.redo
                continue
            record(k, heat)
            if progress is not None and k > shown:
                shown = k
                progress(k, n_frames - 1)
            k += 1
    t_step = time.perf_counter() - t0
    iters = getattr(integ, "iterations", None)
    stress, inversion = monitors[1], monitors[2]
    substeps = stepper.substeps
    return SimResult(
        displacements=out,
        times=frame_dt * np.arange(n_frames),
        kinetic=energy.kinetic,
        strain=energy.strain,
        dissipated=energy.dissipated,
        max_von_mises=stress.max,
        p99_von_mises=stress.p99,
        inverted_count=inversion.count,
        inverted_tets=inversion.tets(),
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
        solver=integ.solver,
        factor_entries=integ.factor_entries,
        check_steps=stepper.check_steps,
        frames_over_tolerance=stepper.over,
    )
