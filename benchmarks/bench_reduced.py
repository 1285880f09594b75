"""Reduced (POD) previews of material variants against their full FEM runs, on the demo.

For the uniform model (the basis material) and the seed's models 1-3, side by side in one
run: the full ``simulate`` wall time (the library call the stage makes, default settings),
the reduced preview's wall time (assembly of the variant's K, M, C, projection, Newmark in
the basis, reconstruction and stress monitors), and the preview's error against the
variant's full run (peak |u - u_full| / peak |u_full|, and RMS), with the residual estimate
that a variant without a full run would get, and its extra time. The basis (the uniform run's
snapshots plus region sensitivities, ``simulate.reduced`` defaults) is built once and timed
apart. Medians over ``--repeats`` runs (default 1: a full run takes 10-30 s here).

Run: .venv/bin/python benchmarks/bench_reduced.py [--repeats 3] [-c configs/meshes/uniform_2mm.yaml]
(``-c``: extra config files merged under each model's, e.g. another tet size.)
The demo's upstream stages (default config and each model's materials) are computed into
data/demo first when the store lacks them (several minutes, once).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path
from typing import Any

from results import Table, describe, record  # benchmarks/results.py, beside this script

from flows.dags import FACE
from physanim.config import load_config
from physanim.fem import reduced
from physanim.fem.model import build_model
from physanim.fem.preview import ReducedParams, build_basis
from physanim.fem.problem import FemProblem
from physanim.fem.simulate import simulate_problem
from physanim.pipeline import stage_inputs
from physanim.pipeline.progress import rich_progress
from physanim.pipeline.spec import dataset_overrides
from tasks.simulate import SimulateStageParams, simulate_inputs

MODELS = ("uniform", "model1", "model2", "model3")


def variant_inputs(model: str, extra: list[Path]) -> tuple[FemProblem, Any, SimulateStageParams]:
    """The FEM problem, the materials output and the stage params of one model, with the
    ``extra`` config files merged over the default."""
    files = [FACE.default_config, *extra]
    if model != "uniform":
        files.append(Path("configs/models") / f"{model}.yaml")
    config, _ = load_config(FACE.config_model(), files, dataset_overrides("demo"))
    with rich_progress() as progress:
        inputs = stage_inputs(FACE, config, "simulate", progress)
    params = config.section("simulate", SimulateStageParams)
    problem, _ = simulate_inputs(**inputs, params=params)
    return problem, inputs["materials"], params


def timed(repeats: int, fn):
    """(median wall s, last result) of ``fn()`` over ``repeats`` calls."""
    walls, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("-c", "--config", type=Path, action="append", default=[],
                        help="extra config file (repeatable), e.g. another tet size")  # fmt: skip
    opts = parser.parse_args()
    variants = {m: variant_inputs(m, opts.config) for m in MODELS}
    full = {}
    for m, (problem, _, params) in variants.items():
        full[m] = timed(opts.repeats, lambda a=problem, p=params: simulate_problem(a, p))
        print(f"full run {m}: {full[m][0]:.1f} s", flush=True)

    problem, materials, params = variants["uniform"]
    bc = problem.conditions
    t0 = time.perf_counter()  # the basis: its own full run of the uniform model, POD, sensitivities
    built = build_basis(problem, materials.tet_labels, params, ReducedParams())
    basis = reduced.PodBasis(built["phi"], built["free"], built["singular_values"])
    free = basis.free
    t_basis = time.perf_counter() - t0
    print(
        f"basis: {basis.size} modes ({len(free)} free DOFs), energy {basis.energy:.7f}, "
        f"built in {t_basis:.1f} s from the uniform run (once per sweep)\n"
    )
    print(
        f"{'variant':9s} {'full s':>7s} {'preview s':>9s} {'speed-up':>8s} "
        f"{'err % peak':>10s} {'err % rms':>9s} {'estimate % peak':>15s} {'estimate s':>10s}"
    )
    rows = []
    for m, (problem, _, params) in variants.items():

        def preview(a=problem, p=params):
            variant = build_model(a.nodes, a.tets, a.materials, p)
            run = reduced.simulate_reduced(
                variant, bc, basis, built["substeps"], actuation=a.actuation
            )
            return variant, run

        wall, (variant, run) = timed(opts.repeats, preview)
        u = run.result.displacements
        error = reduced.displacement_error(u, full[m][1].displacements)
        t0 = time.perf_counter()
        est = reduced.residual_estimate(variant, bc, basis, run, params.solver, problem.actuation)
        t_est = time.perf_counter() - t0
        estimate = reduced.displacement_error(u + est, u)
        print(
            f"{m:9s} {full[m][0]:7.1f} {wall:9.2f} {full[m][0] / wall:7.1f}x "
            f"{100 * error['peak']:10.3f} {100 * error['rms']:9.3f} "
            f"{100 * estimate['peak']:15.3f} {t_est:10.2f}"
        )
        rows.append([m, full[m][0], wall, full[m][0] / wall, 100 * error["peak"],
                     100 * error["rms"], 100 * estimate["peak"], t_est])  # fmt: skip
    n_nodes = len(variants["uniform"][0].nodes)
    mesh = f", {n_nodes} nodes" + "".join(f", {c}" for c in opts.config)
    columns = ["variant", "full_simulate_s", "preview_s", "speed_up", "error_pct_of_peak"]
    columns += ["error_rms_pct", "estimate_pct_of_peak", "estimate_s"]
    record(
        "bench_reduced",
        [
            Table(
                f"previews against full runs (demo{mesh}), medians of {opts.repeats}",
                columns,
                rows,
                notes=f"basis: {basis.size} modes ({len(free)} free DOFs), energy "
                f"{basis.energy:.7f}, built in {t_basis:.1f} s from the uniform run",
            )
        ],  # fmt: skip
        **describe(__doc__, "bench_reduced"),
        headline={
            "preview_s": {"min": min(r[2] for r in rows), "max": max(r[2] for r in rows)},
            "full_s": {"min": min(r[1] for r in rows), "max": max(r[1] for r in rows)},
            "models_error_pct_of_peak": max(r[4] for r in rows[1:]),
            "basis_s": t_basis,
        },  # fmt: skip
    )


if __name__ == "__main__":
    main()
