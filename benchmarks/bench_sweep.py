"""Sweep scaling: four material models on 1 and on 2 Dask workers (same process layout), and
the wall time predicted for N = 1..64 workers from the measured stage times and the DAG.

Prepares a short demo and its shared stages (ingest .. tetra, timed: the serial part of a
cold sweep) once, then runs the same sweep (uniform, model1, model2, model3: materials,
simulate, evaluate, render per variant) on a fresh copy of that store each time, through
Prefect on local Dask workers that each get ``--threads`` numerical threads (default: the
cores over 2, so that the 1- and 2-worker runs differ only in the number of workers).
Prefect's temporary server is started before the timed runs. With ``--repeat N`` the modes
take turns N times and medians are compared; ``--serial`` also times the jobs one after
another in this process without Prefect.

The model (``physanim.pipeline.scaling``): the fixed cost and the per-job overhead are fitted
on the one-worker runs' timelines; a list scheduler plays the sweep's jobs (their measured
seconds plus that overhead) on N workers. It is checked against the 2-worker run twice: with
the one-worker stage times (what N workers with cores of their own would do) and with the
2-worker run's own stage times (the schedule alone). The curve for a cold sweep (shared
stages included, once) of 4 and of 64 variants is printed and plotted to ``--plot``.
Usage: .venv/bin/python benchmarks/bench_sweep.py [--frames 30] [--render-every 1] [--repeat 1]
       [--threads T] [--serial] [--plot out/bench_sweep_scaling.png]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from results import Table, describe, record  # benchmarks/results.py, beside this script

ROOT = Path(__file__).resolve().parents[1]
MODELS = ("uniform", "model1", "model2", "model3")
PER_VARIANT = ("materials", "simulate", "evaluate", "render")
CURVE_WORKERS = range(1, 65)
SHOWN_WORKERS = (1, 2, 3, 4, 8, 16, 32, 64)


def variant_jobs(keys: Mapping[str, Mapping[str, str]], seconds: Mapping[tuple[str, str], float]):
    """The sweep's per-variant jobs (distinct stage outputs) with measured seconds and deps."""
    from flows.dags import FACE
    from physanim.pipeline.scaling import TimedJob

    jobs = {}
    for stage_keys in keys.values():
        for stage in PER_VARIANT:
            name = f"{stage}:{stage_keys[stage]}"
            deps = tuple(
                f"{u}:{stage_keys[u]}" for u in FACE.stage(stage).upstream if u in PER_VARIANT
            )
            jobs[name] = TimedJob(name, seconds[(stage, stage_keys[stage])], deps)
    return list(jobs.values())


def plot_curves(
    curves: Mapping[str, Sequence[float]], measured: Mapping[int, float], path: Path
) -> None:
    """Predicted wall time and speed-up against workers (log2 axis), measured points."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4))
    wall_ax, speed_ax = fig.subplots(1, 2)
    n = list(CURVE_WORKERS)
    for k, (label, walls) in enumerate(curves.items()):
        wall_ax.plot(n, [w / 60 for w in walls], color=f"C{k}", label=label)
        speed_ax.plot(n, [walls[0] / w for w in walls], color=f"C{k}", label=label)
    wall_ax.plot(list(measured), [w / 60 for w in measured.values()], "ko", ms=5,
                 label="measured here (shared stages cached, 2 vCPUs)")  # fmt: skip
    speed_ax.plot(n, n, ":", color="grey", label="ideal (N x)")
    for ax in (wall_ax, speed_ax):
        ax.set_xscale("log", base=2)
        ax.set_xticks(list(SHOWN_WORKERS), [str(x) for x in SHOWN_WORKERS])
        ax.set_xlabel("workers N")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    wall_ax.set_yscale("log")
    wall_ax.set_ylabel("wall time (min)")
    wall_ax.set_title("Predicted sweep wall time")
    speed_ax.set_yscale("log", base=2)
    speed_ax.set_yticks(list(SHOWN_WORKERS), [str(x) for x in SHOWN_WORKERS])
    speed_ax.set_ylabel("speed-up over 1 worker")
    speed_ax.set_title("Predicted speed-up")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--render-every", type=int, default=1, help="render.every_frames (default 1)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per mode, taking turns")
    ap.add_argument("--threads", type=int, default=max(1, (os.cpu_count() or 2) // 2),
                    help="numerical threads per worker (default: cores / 2)")  # fmt: skip
    ap.add_argument("--serial", action="store_true", help="also time the jobs serially")
    ap.add_argument("--plot", type=Path, default=ROOT / "out" / "bench_sweep_scaling.png")
    args = ap.parse_args()

    from flows.dags import FACE
    from flows.prefect_env import configure
    from physanim.config import load_config
    from physanim.pipeline import execute_plan_locally, make_plan
    from physanim.pipeline.scaling import fit_overheads, predict_wall, sweep_jobs
    from physanim.store import StageStore
    from tasks.ingest import ensure_demo

    modes = {
        "1 worker": {"workers": 1, "worker_threads": args.threads},
        "2 workers": {"workers": 2, "worker_threads": args.threads},
    }
    if args.serial:
        modes["serial"] = {"serial": True}
    settings = [f"demo.n_frames={args.frames}", f"render.every_frames={args.render_every}"]
    walls: dict[str, list[float]] = {m: [] for m in modes}
    runs: dict[str, list] = {m: [] for m in modes}  # (outcome, called, returned) per run
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "demo"
        cfg, _ = load_config(
            FACE.config_model(), [FACE.default_config], [f"dataset.dir={data}", *settings]
        )
        ensure_demo(cfg)
        store = StageStore(cfg.dataset.store_path)
        plan = make_plan(FACE, cfg, store)
        shared_stages = FACE.upstream("tetra")
        shared = execute_plan_locally(FACE, cfg, [e for e in plan if e.stage in shared_stages])
        shared_s = {r.stage: r.seconds for r in shared}
        print("shared stages (in this process): "
              + ", ".join(f"{s} {t:.1f} s" for s, t in shared_s.items())
              + f"; {sum(shared_s.values()):.1f} s")  # fmt: skip

        configure(Path(tmp) / "runs")
        from prefect import flow

        from flows.sweep import run_sweep

        t0 = time.perf_counter()
        flow(name="warm-up")(lambda: None)()
        print(f"Prefect temporary server start: {time.perf_counter() - t0:.1f} s")
        for rep in range(args.repeat):
            for mode, kwargs in modes.items():
                copy = Path(tmp) / f"store_{rep}_{mode.replace(' ', '_')}.zarr"
                shutil.copytree(store.root, copy)
                sweep = Path(tmp) / f"sweep_{rep}_{mode.replace(' ', '_')}.yaml"
                lines = ["pipeline: face", f"datasets: [{data}]", "set:"]
                lines += [f"  dataset.store: {copy}"]
                lines += [f"  {s.replace('=', ': ')}" for s in settings]
                lines += ["variants:"] + [
                    f"  - {{name: {m}, configs: [{ROOT / 'configs' / 'models' / m}.yaml]}}"
                    for m in MODELS
                ]
                sweep.write_text("\n".join(lines) + "\n")
                load = os.getloadavg()[0]
                called = time.time()  # the whole call: planning, stages, report, cluster
                outcome = run_sweep(sweep, **kwargs)
                returned = time.time()
                walls[mode].append(returned - called)
                runs[mode].append((outcome, called, returned))
                after = os.getloadavg()[0]
                print(f"  run {rep + 1} {mode:9s}: {walls[mode][-1]:7.1f} s  (load average "
                      f"{load:.1f} before, {after:.1f} after)", flush=True)  # fmt: skip
                shutil.rmtree(copy)

    median = {m: statistics.median(w) for m, w in walls.items()}
    print(
        f"\n{len(MODELS)} variants x ({', '.join(PER_VARIANT)}), {args.frames} frames, "
        f"render.every_frames={args.render_every}, {args.threads} thread(s) per worker, "
        f"{os.cpu_count()} cores; median of {args.repeat} run(s), each the whole run_sweep call:"
    )
    for mode, wall in median.items():
        print(f"  {mode:9s}: {wall:7.1f} s  (runs: {', '.join(f'{w:.1f}' for w in walls[mode])})")
    ratio = median["2 workers"] / median["1 worker"]
    print(f"  2 workers / 1 worker: {ratio:.2f} (ideal 0.50)")

    # the model, fitted on the one-worker runs
    def stage_seconds(mode: str) -> dict[tuple[str, str], float]:
        per_run = [{(r.stage, r.key): r.seconds for r in o.results} for o, _, _ in runs[mode]]
        return {k: statistics.median(run[k] for run in per_run) for k in per_run[0]}

    fits = [fit_overheads(o.results, called, returned) for o, called, returned in runs["1 worker"]]
    fixed = statistics.median(f[0] for f in fits)
    per_job = statistics.median(f[1] for f in fits)
    keys = runs["1 worker"][0][0].variants
    one, two = stage_seconds("1 worker"), stage_seconds("2 workers")
    jobs_one, jobs_two = variant_jobs(keys, one), variant_jobs(keys, two)
    print(f"model: fixed cost {fixed:.1f} s (cluster start, planning, report), "
          f"{per_job:.2f} s overhead per job ({len(jobs_one)} jobs)")  # fmt: skip
    print("  stage seconds summed over the variants, 1 worker / 2 workers:")
    stage_rows = []
    for stage in PER_VARIANT:
        a = sum(t for (s, _), t in one.items() if s == stage)
        b = sum(t for (s, _), t in two.items() if s == stage)
        print(f"    {stage:10s} {a:7.1f} / {b:7.1f}  ({b / a:.2f}x)")
        stage_rows.append([stage, a, b, b / a])
    print("  2 workers, predicted vs measured "
          f"{median['2 workers']:.1f} s: with the 1-worker stage times (workers with cores of "
          f"their own) {predict_wall(jobs_one, 2, fixed, per_job):.1f} s; with the 2-worker "
          f"run's own stage times {predict_wall(jobs_two, 2, fixed, per_job):.1f} s")  # fmt: skip

    # cold sweeps (shared stages once, then V variants) on N workers with cores of their own
    mean = {s: statistics.mean(t for (st, _), t in one.items() if st == s) for s in PER_VARIANT}
    upstream = {s.name: s.upstream for s in FACE.stages}
    chain = sum(mean.values()) + per_job * len(PER_VARIANT)
    serial_part = fixed + sum(shared_s.values()) + per_job * len(shared_s)
    curves = {}
    curve_rows = []
    for variants in (len(MODELS), 16, 64):
        jobs = sweep_jobs(shared_s, mean, upstream, variants)
        walls_n = [predict_wall(jobs, n, fixed, per_job) for n in CURVE_WORKERS]
        curves[f"{variants} variants"] = walls_n
        cells = "  ".join(f"N={n}: {walls_n[n - 1] / 60:5.1f}" for n in SHOWN_WORKERS)
        curve_rows.append([variants, *(walls_n[n - 1] / 60 for n in SHOWN_WORKERS),
                           walls_n[0] / walls_n[variants - 1]])  # fmt: skip
        print(f"  cold sweep of {variants:2d} variants, predicted wall (min): {cells}")
        print(f"    speed-up at N = V: {walls_n[0] / walls_n[variants - 1]:.1f}x; floor "
              f"{(serial_part + chain) / 60:.1f} min = serial part {serial_part / 60:.1f} min "
              f"(fixed + shared stages) + one variant's chain {chain / 60:.1f} min")  # fmt: skip
    warm = [predict_wall(jobs_one, n, fixed, per_job) for n in CURVE_WORKERS]
    curves[f"{len(MODELS)} variants, shared stages cached (as measured)"] = warm
    measured = {1: median["1 worker"], 2: median["2 workers"]}
    plot_curves(curves, measured, args.plot)
    print(f"  plot: {args.plot}")
    model = [
        ["fixed cost", fixed, "s"],
        ["overhead per job", per_job, "s"],
        ["shared stages", sum(shared_s.values()), "s"],
        ["a variant's chain", chain, "s"],
        [
            "2 workers predicted, 1-worker stage times",
            predict_wall(jobs_one, 2, fixed, per_job),
            "s",
        ],
        ["2 workers predicted, own stage times", predict_wall(jobs_two, 2, fixed, per_job), "s"],
    ]
    record(
        "bench_sweep",
        [
            Table(
                f"{len(MODELS)} variants, {args.frames} frames, whole run_sweep call, median of "
                f"{args.repeat}",
                ["mode", "wall_s", "runs_s"],
                [[m, median[m], walls[m]] for m in modes],
                notes=f"2 workers / 1 worker: {ratio:.2f}",
            ),
            Table(
                "stage seconds summed over the variants",
                ["stage", "one_worker_s", "two_workers_s", "ratio"],
                stage_rows,
            ),
            Table(
                "the scaling model, fitted on the one-worker runs",
                ["figure", "value", "unit"],
                model,
            ),
            Table(
                "predicted cold sweeps, workers with cores of their own",
                ["variants", *(f"N{n}_min" for n in SHOWN_WORKERS), "speed_up_at_N_equal_variants"],
                curve_rows,
            ),
        ],
        **describe(__doc__, "bench_sweep"),
        headline={
            "one_worker_s": median["1 worker"],
            "two_workers_s": median["2 workers"],
            "ratio": ratio,
        },
    )


if __name__ == "__main__":
    main()
