"""Benchmark of a cold face pipeline run on the demo: where the time goes.

In fresh dataset folders under ``data/`` (removed at the end unless ``--keep``), one after the
other in one run:
1. the reference: the demo generated with one process (as before issue #20), timed (wall, CPU);
2. ``physanim run --dataset <empty folder>``, exactly what ``make pipeline`` runs on a fresh
   clone: it generates the demo (worker processes, one per core) while Prefect's shared server
   starts, then runs every stage. Printed: the demo generation as the run reports it, each
   stage's wall time (its ``duration_s`` in the store), the time while any stage ran (stages
   side by side, scan beside ingest and tiles beside tetra, counted once), the rest (Python
   start, CLI, planning, Prefect's server and flow, the report), and the run's wall and CPU
   time.

Wall times on a shared machine are noisy: the load average before and after is printed with
them; compare CPU times too.

Usage: .venv/bin/python benchmarks/bench_cold.py [--frames 90] [--keep]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import time
from datetime import datetime
from pathlib import Path

from results import Table, describe, record  # benchmarks/results.py, beside this script

from flows.dags import FACE
from physanim.capture.demo import default_workers, generate_demo
from physanim.store import StageStore

#: The face DAG's stages, in order
STAGES = tuple(s.name for s in FACE.stages)


def _cpu_s(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def timed_demo(out: Path, frames: int, workers: int) -> tuple[float, float]:
    """(wall s, CPU s of this process and its workers) of one demo generation into ``out``."""
    t0, c0 = time.perf_counter(), _cpu_s(resource.RUSAGE_SELF) + _cpu_s(resource.RUSAGE_CHILDREN)
    generate_demo(out, n_frames=frames, workers=workers)
    cpu = _cpu_s(resource.RUSAGE_SELF) + _cpu_s(resource.RUSAGE_CHILDREN) - c0
    return time.perf_counter() - t0, cpu


def busy_span(spans: list[tuple[float, float]]) -> float:
    """Seconds covered by the union of (start, end) intervals: stages that run side by side
    (scan beside ingest, tiles beside tetra) count once."""
    total, reach = 0.0, float("-inf")
    for start, end in sorted(spans):
        if end > reach:
            total += end - max(start, reach)
            reach = end
    return total


def cold_run(dataset: Path, frames: int) -> tuple[float, float, float, dict[str, float], float]:
    """``physanim run`` on an empty dataset folder: (wall s, CPU s, demo generation s as the
    run printed it, each stage's wall s, seconds while any stage ran)."""
    cmd = [".venv/bin/physanim", "run", "-p", "face", "--dataset", str(dataset),
           "--set", f"demo.n_frames={frames}"]  # fmt: skip
    c0, t0 = _cpu_s(resource.RUSAGE_CHILDREN), time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _cpu_s(resource.RUSAGE_CHILDREN) - c0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stdout[-3000:]}{done.stderr[-3000:]}")
    demo = re.search(r"generated \S+ in ([0-9.]+) s", done.stdout + done.stderr)
    if demo is None:
        raise SystemExit(f"{' '.join(cmd)} did not generate the demo:\n{done.stdout[-3000:]}")
    store = StageStore(dataset / "runs" / "store.zarr", create=False)
    keys = store.runs()[0].keys
    provenance = {s: store.provenance(s, keys[s]) for s in STAGES}
    seconds = {s: float(p["duration_s"]) for s, p in provenance.items()}
    spans = [
        (datetime.fromisoformat(p["started"]).timestamp(),
         datetime.fromisoformat(p["finished"]).timestamp())
        for p in provenance.values()
    ]  # fmt: skip
    return wall, cpu, float(demo.group(1)), seconds, busy_span(spans)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=90, help="demo frames (90: the default demo)")
    ap.add_argument("--keep", action="store_true", help="keep the dataset folders")
    args = ap.parse_args()
    root = Path("data") / f"bench-cold-{os.getpid()}"
    loads = [os.getloadavg()[0]]
    try:
        ref_wall, ref_cpu = timed_demo(root / "serial" / "demo", args.frames, 1)
        loads.append(os.getloadavg()[0])
        run_wall, run_cpu, demo_s, seconds, busy = cold_run(root / "demo", args.frames)
        loads.append(os.getloadavg()[0])
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)

    print(f"cold face pipeline on the demo ({args.frames} frames); load average (1 min) at the "
          f"start, before and after the run: {', '.join(f'{x:.1f}' for x in loads)}")  # fmt: skip
    print(f"{'part':<48s} {'wall s':>8s} {'CPU s':>8s}")
    print(f"{'reference: demo generation, 1 process':<48s} {ref_wall:8.1f} {ref_cpu:8.1f}")
    print(f"{'physanim run on an empty folder (cold)':<48s} {run_wall:8.1f} {run_cpu:8.1f}")
    workers = default_workers()
    print(f"  {f'demo generation, {workers} worker processes':<46s} {demo_s:8.1f}")
    for s in STAGES:
        print(f"  {s:<46s} {seconds[s]:8.1f}")
    rest = run_wall - demo_s - busy  # stages side by side count once
    print(f"  {'stages (side by side counted once)':<46s} {busy:8.1f}")
    print(f"  {'the rest (start, CLI, Prefect, report)':<46s} {rest:8.1f}")
    rows = [["reference: demo generation, 1 process", ref_wall, ref_cpu],
            ["physanim run on an empty folder (cold)", run_wall, run_cpu],
            [f"demo generation, {workers} worker processes", demo_s, None],
            *[[s, seconds[s], None] for s in STAGES],
            ["stages (side by side counted once)", busy, None],
            ["the rest (start, CLI, Prefect, report)", rest, None]]  # fmt: skip
    record(
        "bench_cold",
        [
            Table(
                f"cold face pipeline on the demo ({args.frames} frames)",
                ["part", "wall_s", "cpu_s"],
                rows,
                reference="the demo generated by one process",
            )
        ],  # fmt: skip
        **describe(__doc__, "bench_cold"),
        host={"load_average_during": loads},
        headline={
            "cold_run_s": run_wall,
            "demo_s": demo_s,
            "tetra_s": seconds.get("tetra"),
            "simulate_s": seconds.get("simulate"),
            "render_s": seconds.get("render"),
        },  # fmt: skip
    )


if __name__ == "__main__":
    main()
