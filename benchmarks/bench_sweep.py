"""Sweep wall time: four material models on 2 Dask workers vs one after another, same run.

Prepares a short demo and its shared stages (ingest .. tetra) once, copies the store per mode,
then runs the same sweep (uniform, model1, model2, model3: materials, simulate, evaluate,
render per variant) three ways: serially in this process without Prefect, through Prefect on
one Dask worker (all cores), and through Prefect on ``--workers`` Dask workers (the cores
shared out). Prefect's temporary server is started before the timed runs, so both Prefect
runs pay only their own cluster start.
Usage: python benchmarks/bench_sweep.py [--frames 30] [--workers 2]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODELS = ("uniform", "model1", "model2", "model3")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()

    from flows.dags import FACE
    from flows.prefect_env import configure
    from physanim.config import load_config
    from physanim.pipeline import execute_plan_locally, make_plan
    from physanim.store import StageStore
    from tasks.ingest import ensure_demo

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "demo"
        base = [f"dataset.dir={data}", f"demo.n_frames={args.frames}", "render.every_frames=3"]
        cfg, _ = load_config(FACE.config_model(), [FACE.default_config], base)
        ensure_demo(cfg)
        store = StageStore(cfg.dataset.store_path)
        plan = make_plan(FACE, cfg, store, only=None)
        upstream = [e for e in plan if e.stage in FACE.upstream("tetra")]
        t0 = time.perf_counter()
        execute_plan_locally(FACE, cfg, upstream)
        print(f"shared stages (ingest..tetra): {time.perf_counter() - t0:.1f} s")

        sweeps, outcomes = {}, {}
        for mode in ("serial", "dask1", "dask"):
            copy = Path(tmp) / f"store_{mode}.zarr"
            shutil.copytree(store.root, copy)
            sweep = Path(tmp) / f"sweep_{mode}.yaml"
            lines = ["pipeline: face", f"datasets: [{data}]", "set:", f"  dataset.store: {copy}"]
            lines += [f"  {s}" for s in (f"demo.n_frames: {args.frames}", "render.every_frames: 3")]
            lines.append("variants:")
            lines += [
                f"  - {{name: {m}, configs: [{ROOT / 'configs' / 'models' / (m + '.yaml')}]}}"
                for m in MODELS
            ]
            sweep.write_text("\n".join(lines) + "\n")
            sweeps[mode] = sweep

        configure(Path(tmp) / "runs")
        from prefect import flow

        from flows.sweep import run_sweep

        t0 = time.perf_counter()
        flow(name="warm-up")(lambda: None)()
        print(f"Prefect temporary server start: {time.perf_counter() - t0:.1f} s")
        walls = {}
        for mode, kwargs in (("serial", {"serial": True}), ("dask1", {"workers": 1}),
                             ("dask", {"workers": args.workers})):  # fmt: skip
            t0 = time.perf_counter()  # the whole call: planning, stages, report, cluster close
            outcomes[mode] = run_sweep(sweeps[mode], **kwargs)
            walls[mode] = time.perf_counter() - t0
        timeline = ROOT / "out" / "bench_sweep_timeline.png"  # the report's, kept
        timeline.parent.mkdir(exist_ok=True)
        shutil.copyfile(outcomes["dask"].report_path.parent / "timeline.png", timeline)
    serial, one, dask = (outcomes[m] for m in ("serial", "dask1", "dask"))
    print(f"{len(MODELS)} variants x (materials, simulate, evaluate, render), {args.frames} frames")
    print("  wall time of each run_sweep call (planning, stages, report, cluster start/close):")
    print(
        f"  serial, one process, no Prefect : {walls['serial']:7.1f} s  "
        f"({len(serial.results)} runs)"
    )
    print(f"  Prefect + Dask, 1 worker        : {walls['dask1']:7.1f} s  ({len(one.results)} runs)")
    print(
        f"  Prefect + Dask, {args.workers} workers       : {walls['dask']:7.1f} s  "
        f"({len(dask.results)} runs)  ratio to 1 worker {walls['dask'] / walls['dask1']:.2f}, "
        f"to serial {walls['dask'] / walls['serial']:.2f}"
    )
    print(f"  stage runs per worker of the {args.workers}-worker run: {timeline}")
    print("  stage seconds summed over variants (serial / 1 worker / 2 workers):")
    for stage in dict.fromkeys(r.stage for r in serial.results):
        sums = [sum(r.seconds for r in o.results if r.stage == stage) for o in (serial, one, dask)]
        print(f"    {stage:10s} " + " / ".join(f"{x:6.1f}" for x in sums))


if __name__ == "__main__":
    main()
