"""Benchmark the FEM core on the demo face mesh (~15k DOF): the demo's ``simulate`` wall time
and error against a dt = 0.5 ms float64 reference (fixed 1 ms steps, the first default;
adaptive steps by step doubling, the second; adaptive steps by the acceleration estimate with a
float64 factor, the third; the same with a float32 factor, the default; and in mixed precision;
medians of 3 runs), the
BLAS under CHOLMOD, CHOLMOD's factorisations; then assembly, factorisation, time per Newmark
step and real-time factor per solver, next to a plain-SuperLU baseline.

Run: .venv/bin/python benchmarks/bench_fem.py [--baseline-steps 100] [--repeats 3]
Mesh, materials, fixed (bone-side) and driven nodes and the driven landmark trajectories are the
demo pipeline's own (default config): its align, tetra and materials stages, computed into
data/demo first when the store lacks them (several minutes, once).
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time
from typing import Any

import numba
import numpy as np
import scipy.sparse as sp
from results import Table, describe, record  # benchmarks/results.py, beside this script
from threadpoolctl import threadpool_limits

from flows.dags import FACE
from physanim.config import load_config
from physanim.fem.geometry import node_dofs
from physanim.fem.linsolve import CholmodFactors, blas_in_use
from physanim.fem.model import build_model
from physanim.fem.newmark import Newmark, State
from physanim.fem.params import SimulateParams
from physanim.fem.pardiso import PardisoFactors, has_pardiso
from physanim.fem.problem import FemProblem
from physanim.fem.simulate import frames_per_thread_count, simulate_problem
from physanim.pipeline import stage_inputs
from physanim.pipeline.progress import rich_progress
from physanim.pipeline.spec import dataset_overrides
from tasks.simulate import SimulateStageParams, simulate_inputs


def demo_inputs() -> tuple[FemProblem, SimulateStageParams]:
    """The FEM problem and the stage parameters of the demo (default config)."""
    config, _ = load_config(FACE.config_model(), [FACE.default_config], dataset_overrides("demo"))
    with rich_progress() as progress:
        inputs = stage_inputs(FACE, config, "simulate", progress)
    params = config.section("simulate", SimulateStageParams)
    problem, _ = simulate_inputs(**inputs, params=params)
    return problem, params


def time_steps(model, pres, dt, solver, n_steps):
    """Factorisation and per-step time of the linear Newmark with one solver."""
    t0 = time.perf_counter()
    nm = Newmark(model.K, model.M, model.C, dt, pres, solver, model.split)
    t_fac = time.perf_counter() - t0
    state = State.rest(model.n_dofs)
    rng = np.random.default_rng(2)
    d_c = rng.normal(size=len(pres)) * 1e-4
    z = np.zeros(len(pres))
    t0 = time.perf_counter()
    for i in range(n_steps):
        nm.step(state, d_c * np.sin(i * dt * 10), z, z)
    return t_fac, (time.perf_counter() - t0) / n_steps, nm


def compare_stepping(sim: FemProblem, params: SimulateStageParams, repeats: int) -> Table:
    """The demo's simulate: reference, previous default and fast paths side by side (the
    printed table, returned for the results file: wall times in s, errors in % and mm)."""
    print(f"BLAS under CHOLMOD: {blas_in_use()}; numba threads: {numba.get_num_threads()}")
    t0 = time.perf_counter()
    ref_params = params.model_copy(update={"dt": 5e-4, "stepping": "fixed"})
    ref = simulate_problem(sim, ref_params).displacements.astype(np.float64)
    t_ref = time.perf_counter() - t0
    print(f"reference: fixed dt = 0.5 ms, float64, in {t_ref:.1f} s (once)")
    recorded = [["reference: fixed dt = 0.5 ms, float64 (once)", t_ref, [t_ref], *[None] * 4, 0, 0]]
    peak = np.linalg.norm(ref, axis=2).max()
    rows = [
        ("fixed dt = 1 ms (first default)", {"stepping": "fixed"}),
        ("adaptive, step doubling, 0.03 mm", {"error_estimate": "doubling", "error_tol_mm": 0.03}),
        ("adaptive, float64 factor (third default)", {"precision": "float64"}),
        ("adaptive, float32 factor (default)", {}),
        ("adaptive, mixed precision", {"precision": "mixed"}),
    ]
    print(
        f"\n{'simulate on the demo (3 s)':40s} {'wall s':>7s} {'runs s':>18s} {'steps':>6s} "
        f"{'check':>6s} {'factor s':>8s} {'threads:frames':>14s} {'err % peak':>10s} {'err mm':>7s}"
    )
    for name, update in rows:
        walls, res = [], None
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = simulate_problem(sim, params.model_copy(update=update))
            walls.append(time.perf_counter() - t0)
        err = np.linalg.norm(res.displacements - ref, axis=2).max()
        per_count = frames_per_thread_count(res.solver_threads).items()
        threads = " ".join(f"{n}:{k}" for n, k in per_count)  # threads: frames
        runs = ", ".join(f"{w:.1f}" for w in walls)
        print(
            f"{name:40s} {statistics.median(walls):7.2f} {runs:>18s} "
            f"{res.frame_substeps.sum():6d} {res.check_steps:6d} "
            f"{res.timings['factorization']:8.2f} {threads:>14s} {100 * err / peak:10.3f} "
            f"{err * 1e3:7.4f}"
        )
        recorded.append([name, statistics.median(walls), walls, int(res.frame_substeps.sum()),
                         res.check_steps, res.timings["factorization"], threads,
                         100 * err / peak, err * 1e3])  # fmt: skip
    print(f"(peak displacement {peak * 1e3:.2f} mm; err: largest node distance to the reference)")
    columns = ["mode", "wall_s", "runs_s", "steps", "check_steps", "factorisation_s"]
    columns += ["threads_frames", "error_pct_of_peak", "error_mm"]
    return Table("simulate on the demo (3 s)", columns, recorded,
                 notes=f"peak displacement {peak * 1e3:.2f} mm; BLAS under CHOLMOD: "
                 f"{blas_in_use()}; numba threads: {numba.get_num_threads()}")  # fmt: skip


def compare_factorizations(sim: FemProblem, repeats: int) -> Table:
    """Refactorising the demo's Newmark matrix (one frame per step) after the symbolic
    analysis, up to a ready solver: PARDISO's LDL^T of the sparser augmented matrix (the
    default where MKL installs), CHOLMOD's supernodal LL^T of A_uu (BLAS-3) and its simplicial
    LDL^T of the augmented matrix."""
    model = build_model(sim.nodes, sim.tets, sim.materials)
    pres = node_dofs(sim.conditions.driven_idx)
    springs = sim.conditions.springs
    ks = 0 if springs is None else springs.matrix(model.n_dofs)
    nm = Newmark(model.K + ks, model.M, model.C, sim.frame_dt, pres, "cholmod")
    h, u = nm.dt, nm.free
    K_el, G, w = model.split
    A_el = (K_el + ks + 4 / h**2 * model.M + 2 / h * model.C).tocsr()[u][:, u]
    aug = sp.bmat([[A_el, G.tocsr()[:, u].T], [G.tocsr()[:, u], sp.diags(-1 / w)]], format="csc")
    print(
        f"\n{'Newmark refactorisation, to a ready solver':52s} {'s (median)':>10s} {'L nnz':>10s}"
    )
    recorded = []

    def measure(label: str, factors: Any, A: sp.spmatrix) -> None:
        factors(A)  # symbolic analysis, first numeric factor, solver layout
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            factors(A)
            times.append(time.perf_counter() - t0)
        nnz = factors.factor_entries
        print(f"{label:52s} {statistics.median(times):10.3f} {nnz / 1e6:9.2f}M")
        recorded.append([label, statistics.median(times), nnz / 1e6])

    if has_pardiso():
        for dtype in (np.float32, np.float64):
            name = f"PARDISO LDL^T of the augmented matrix, {np.dtype(dtype).name}"
            measure(name, PardisoFactors("indefinite", dtype, slots=2), aug)
    for name, mode, A in (
        ("CHOLMOD supernodal LL^T of A_uu", "supernodal", nm.A_uu),
        ("CHOLMOD simplicial LDL^T of the augmented matrix", "simplicial", aug),
    ):
        for threads in (numba.get_num_threads(), 1):
            with threadpool_limits(limits=threads, user_api="blas"):
                measure(f"{name}, {threads} BLAS thread(s)", CholmodFactors(mode), A)
    return Table("Newmark refactorisation, to a ready solver", ["factorisation", "median_s",
                 "factor_nnz_millions"], recorded)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--baseline-steps", type=int, default=100, help="steps per solver row")
    ap.add_argument("--repeats", type=int, default=3, help="runs per simulate row")
    args = ap.parse_args()

    sim, params = demo_inputs()
    nodes, tets, mat = sim.nodes, sim.tets, sim.materials
    driven, springs = sim.conditions.driven_idx, sim.conditions.springs
    traj = sim.conditions.values.reshape(sim.n_frames, -1, 3)  # (T, n_d, 3) m
    print(
        f"demo mesh: {len(nodes)} nodes, {len(tets)} tets, {3 * len(nodes)} DOF "
        f"({len(driven)} prescribed bone-side nodes, "
        f"{0 if springs is None else len(springs.nodes)} skin nodes on springs); "
        f"{len(traj)} frames at {1 / sim.frame_dt:.0f} fps"
    )
    stepping = compare_stepping(sim, params, args.repeats)
    factorisations = compare_factorizations(sim, args.repeats)
    per_solver = []
    pres = node_dofs(driven)
    dt = params.dt

    all_threads = numba.get_num_threads()
    print(f"\n{'config':34s} {'assembly s':>10s} {'factor s':>9s} {'ms/step':>8s} {'RTF':>6s}")
    for form in ("anp", "p1"):
        t0 = time.perf_counter()
        model = build_model(nodes, tets, mat, SimulateParams(formulation=form))
        t_asm = time.perf_counter() - t0
        pardiso = [("pardiso", all_threads)] if has_pardiso() else []
        for solver, threads in (*pardiso, ("cholmod", all_threads), ("cholmod", 1),
                                ("superlu", 1), ("superlu_colamd", 1)):  # fmt: skip
            numba.set_num_threads(threads)  # our solve and products; SuperLU is serial anyway
            t_fac, per_step, _ = time_steps(model, pres, dt, solver, args.baseline_steps)
            numba.set_num_threads(all_threads)
            threaded = solver in ("pardiso", "cholmod")
            name = f"{form} / {solver}" + (f", {threads} thread(s)" if threaded else "")
            print(
                f"{name:34s} {t_asm:10.2f} {t_fac:9.2f} {1e3 * per_step:8.2f} {dt / per_step:6.2f}"
            )
            per_solver.append([name, t_asm, t_fac, 1e3 * per_step, dt / per_step])

    res = simulate_problem(sim, params.model_copy(update={"stepping": "fixed"}))
    n_steps = (len(traj) - 1) * res.n_substeps
    tm = res.timings
    per_step = tm["stepping"] / n_steps
    print(
        f"\ndemo simulate, fixed steps (anp, consistent mass, auto solver): {n_steps} steps of "
        f"{res.dt * 1e3:.3f} ms in {tm['stepping']:.2f} s = {1e3 * per_step:.2f} ms/step incl. "
        f"per-frame energies, stress, inversion check; 1,000 steps in {1e3 * per_step:.2f} s "
        f"(target < 10 s); RTF {res.dt / per_step:.2f}; assembly {tm['assembly']:.2f} s, "
        f"factorisation {tm['factorization']:.2f} s"
    )
    print(
        f"  max |d| {np.abs(res.displacements).max() * 1e3:.2f} mm, max von Mises "
        f"{res.max_von_mises.max():.0f} Pa, inverted tets {res.inverted_tets.size}"
    )

    n_cor = 3
    cor = params.model_copy(update={"corotational": True})
    # corotational: no springs
    short = FemProblem.driven(nodes, tets, mat, driven, traj[: n_cor + 1], sim.frame_dt)
    res_c = simulate_problem(short, cor)
    steps_c = n_cor * res_c.n_substeps
    print(
        f"corotational: {1e3 * res_c.timings['stepping'] / steps_c:.1f} ms/step over {steps_c} "
        f"steps, PCG iterations/step mean {res_c.corot_iterations.mean():.1f}"
    )
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {rss:.0f} MiB")
    default = stepping.rows[-2]  # adaptive, float32 factor (default)
    fixed_run = [
        ["fixed steps: steps", n_steps, "count"],
        ["fixed steps: time per step incl. per-frame outputs", 1e3 * per_step, "ms"],
        ["fixed steps: assembly", tm["assembly"], "s"],
        ["fixed steps: factorisation", tm["factorization"], "s"],
        ["corotational: time per step", 1e3 * res_c.timings["stepping"] / steps_c, "ms"],
        ["corotational: PCG iterations per step, mean", res_c.corot_iterations.mean(), "count"],
        ["peak RSS", rss, "MiB"],
    ]
    record(
        "bench_fem",
        [
            stepping,
            factorisations,
            Table(
                "per solver, Newmark steps",
                ["config", "assembly_s", "factor_s", "ms_per_step", "real_time_factor"],
                per_solver,
            ),  # fmt: skip
            Table(
                "demo simulate, fixed steps; corotational; memory",
                ["figure", "value", "unit"],
                fixed_run,
            ),  # fmt: skip
        ],
        **describe(__doc__, "bench_fem"),
        notes=f"demo mesh: {len(nodes)} nodes, {len(tets)} tets, {3 * len(nodes)} DOF",
        headline={
            "nodes": len(nodes),
            "default_s": default[1],
            "reference_s": stepping.rows[0][1],
            "error_pct_of_peak": default[7],
        },  # fmt: skip
    )


if __name__ == "__main__":
    main()
