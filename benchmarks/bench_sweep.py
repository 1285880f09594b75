"""Sweep wall time: four material models on 2 Dask workers vs one after another, same run.

Prepares a short demo and its shared stages (ingest .. tetra) once, then runs the same sweep
(uniform, model1, model2, model3: materials, simulate, evaluate, render per variant) on a fresh
copy of that store each time: serially in this process without Prefect, through Prefect on
``--workers`` Dask workers (the cores shared out) and, unless skipped, on one Dask worker (all
cores). Prefect's temporary server is started before the timed runs, so the Prefect runs pay
only their own cluster start. Each run is timed over its whole ``run_sweep`` call. With
``--repeat N`` the modes take turns N times (this machine's speed drifts by 10-20 % over
minutes) and the medians are compared. Rendering uses the pipeline's default (every frame)
unless ``--render-every`` says otherwise.
Usage: python benchmarks/bench_sweep.py [--frames 30] [--workers 2] [--render-every 1]
       [--repeat 1] [--skip-one-worker]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODELS = ("uniform", "model1", "model2", "model3")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--render-every", type=int, default=1, help="render.every_frames (default 1)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per mode, taking turns")
    ap.add_argument("--skip-one-worker", action="store_true", help="no 1-worker Dask run")
    args = ap.parse_args()

    from flows.dags import FACE
    from flows.prefect_env import configure
    from physanim.config import load_config
    from physanim.pipeline import execute_plan_locally, make_plan
    from physanim.store import StageStore
    from tasks.ingest import ensure_demo

    modes = {"serial": {"serial": True}, "dask": {"workers": args.workers}}
    if not args.skip_one_worker:
        modes["dask1"] = {"workers": 1}
    labels = {
        "serial": "serial, one process, no Prefect",
        "dask": f"Prefect + Dask, {args.workers} workers",
        "dask1": "Prefect + Dask, 1 worker",
    }
    settings = [f"demo.n_frames={args.frames}", f"render.every_frames={args.render_every}"]
    walls: dict[str, list[float]] = {m: [] for m in modes}
    stage_s: dict[str, dict[str, list[float]]] = {m: {} for m in modes}
    timeline = ROOT / "out" / "bench_sweep_timeline.png"  # the last Dask run's, kept
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "demo"
        cfg, _ = load_config(
            FACE.config_model(), [FACE.default_config], [f"dataset.dir={data}", *settings]
        )
        ensure_demo(cfg)
        store = StageStore(cfg.dataset.store_path)
        plan = make_plan(FACE, cfg, store)
        t0 = time.perf_counter()
        execute_plan_locally(FACE, cfg, [e for e in plan if e.stage in FACE.upstream("tetra")])
        print(f"shared stages (ingest..tetra): {time.perf_counter() - t0:.1f} s")

        configure(Path(tmp) / "runs")
        from prefect import flow

        from flows.sweep import run_sweep

        t0 = time.perf_counter()
        flow(name="warm-up")(lambda: None)()
        print(f"Prefect temporary server start: {time.perf_counter() - t0:.1f} s")
        for rep in range(args.repeat):
            for mode, kwargs in modes.items():
                copy = Path(tmp) / f"store_{mode}_{rep}.zarr"
                shutil.copytree(store.root, copy)
                sweep = Path(tmp) / f"sweep_{mode}_{rep}.yaml"
                lines = ["pipeline: face", f"datasets: [{data}]", "set:"]
                lines += [f"  dataset.store: {copy}"]
                lines += [f"  {s.replace('=', ': ')}" for s in settings]
                lines += ["variants:"] + [
                    f"  - {{name: {m}, configs: [{ROOT / 'configs' / 'models' / m}.yaml]}}"
                    for m in MODELS
                ]
                sweep.write_text("\n".join(lines) + "\n")
                t0 = time.perf_counter()  # the whole call: planning, stages, report, cluster
                outcome = run_sweep(sweep, **kwargs)
                walls[mode].append(time.perf_counter() - t0)
                print(f"  run {rep + 1} {labels[mode]:32s}: {walls[mode][-1]:7.1f} s", flush=True)
                for r in outcome.results:
                    stage_s[mode].setdefault(r.stage, [0.0] * args.repeat)[rep] += r.seconds
                if mode == "dask":
                    timeline.parent.mkdir(exist_ok=True)
                    shutil.copyfile(outcome.report_path.parent / "timeline.png", timeline)
                shutil.rmtree(copy)

    median = {m: statistics.median(w) for m, w in walls.items()}
    print(
        f"{len(MODELS)} variants x (materials, simulate, evaluate, render), {args.frames} frames, "
        f"render.every_frames={args.render_every}; median of {args.repeat} run(s) per mode, "
        "each the whole run_sweep call (planning, stages, report, cluster start/close):"
    )
    for mode, wall in median.items():
        runs = ", ".join(f"{w:.1f}" for w in walls[mode])
        print(f"  {labels[mode]:32s}: {wall:7.1f} s  (runs: {runs})")
    ratios = [f"to serial {median['dask'] / median['serial']:.2f}"]
    if "dask1" in median:
        ratios.append(f"to 1 worker {median['dask'] / median['dask1']:.2f}")
    print(f"  {args.workers} workers: ratio " + ", ".join(ratios))
    print(f"  stage runs per worker of the last {args.workers}-worker run: {timeline}")
    print("  median stage seconds summed over variants (" + " / ".join(modes) + "):")
    for stage in stage_s["serial"]:
        sums = [statistics.median(stage_s[m].get(stage, [0.0])) for m in modes]
        print(f"    {stage:10s} " + " / ".join(f"{x:6.1f}" for x in sums))


if __name__ == "__main__":
    main()
