"""Sweep wall time: four material models on 2 Dask workers vs one after another, same run.

Prepares a short demo and its shared stages (ingest .. tetra) once, copies the store twice,
then runs the same sweep (uniform, model1, model2, model3: materials, simulate, evaluate,
render per variant) serially in this process and on a local Dask cluster through Prefect.
Usage: python benchmarks/bench_sweep.py [--frames 30]
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
        upstream = [e for e in plan if e.stage in ("ingest", "track", "fit", "align", "tetra")]
        t0 = time.perf_counter()
        execute_plan_locally(FACE, cfg, upstream)
        print(f"shared stages (ingest..tetra): {time.perf_counter() - t0:.1f} s")

        sweeps = {}
        for mode in ("serial", "dask"):
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
        from flows.sweep import run_sweep

        serial = run_sweep(sweeps["serial"], serial=True)
        dask = run_sweep(sweeps["dask"], workers=args.workers)
    print(f"{len(MODELS)} variants x (materials, simulate, evaluate, render), {args.frames} frames")
    print(f"  serial, one process : {serial.seconds:7.1f} s  ({len(serial.results)} stage runs)")
    print(
        f"  Dask, {args.workers} workers     : {dask.seconds:7.1f} s  ({len(dask.results)} stage "
        f"runs; includes Prefect and cluster start)  ratio {dask.seconds / serial.seconds:.2f}"
    )


if __name__ == "__main__":
    main()
