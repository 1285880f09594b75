"""Benchmark of the face pipeline on the performance library: how well the kinematic scan and
the FEM follow each expression of each performance, region by region.

For each selected performance of ``physanim.capture.library`` (the held-out part by default)
it runs ``physanim run -p face --dataset <root>/<performance>-s<seed>[-coarse]`` (the run
generates a missing dataset from its name first) and reads the evaluate stage's summary:
at each expression's peak frame, the relative displacement error (0: moves like the truth,
1: does not move) of the kinematic scan and of the FEM skin, overall and per facial region,
and the tets the simulation turned inside out there. Printed as tables and recorded in
``benchmarks/results/bench_library.json``.

The full library at 90 frames takes long (a face pipeline run per dataset): choose the part,
``--only`` some performances, and ``--coarse`` (24 frames) with a coarse config to try it.

Usage: python benchmarks/bench_library.py [--part held-out|tuning|all] [--only NAME ...]
    [--seed 0] [--coarse] [--root data/library] [-c CONFIG ...] [--set KEY=VALUE ...]
    [--results DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import time
from pathlib import Path
from typing import Any

from results import RESULTS_DIR, Table, describe, record  # benchmarks/results.py, beside this

from physanim.capture.library import HELD_OUT, PERFORMANCE_NAMES, TUNING, dataset_name
from physanim.store import StageStore

PARTS = {"held-out": HELD_OUT, "tuning": TUNING, "all": PERFORMANCE_NAMES}
COLUMNS = ["performance", "peak", "frame", "region", "kinematic_rel_error", "fem_rel_error"]
INVERTED_COLUMNS = ["performance", "peak", "frame", "inverted_tets"]


def run_pipeline(dataset: Path, configs: list[str], sets: list[str]) -> float:
    """``physanim run`` of the face pipeline on ``dataset``; its wall time, s."""
    cmd = [".venv/bin/physanim", "run", "-p", "face", "--dataset", str(dataset)]
    cmd += [a for c in configs for a in ("-c", c)] + [a for s in sets for a in ("--set", s)]
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stdout[-3000:]}{done.stderr[-3000:]}")
    return time.perf_counter() - start


def peak_rows(performance: str, summary: dict[str, Any]) -> list[list[Any]]:
    """Table rows (``COLUMNS``) of one run's evaluate summary: per peak and region (overall
    first), the kinematic and FEM relative displacement errors (None: nothing moved)."""
    fidelity = summary["fidelity"]
    rows = []
    for peak, frame in summary["peak_frames"].items():
        kin, fem = fidelity["kinematic"][peak], fidelity["fem"][peak]
        rows += [[performance, peak, frame, r, kin.get(r), fem.get(r)] for r in kin]
    return rows


def inverted_rows(performance: str, summary: dict[str, Any]) -> list[list[Any]]:
    """Table rows (``INVERTED_COLUMNS``) of one run's evaluate summary: the tets the
    simulation turned inside out at each peak."""
    at_peaks = summary["inverted_tets_at_peaks"]
    return [[performance, p, f, at_peaks[p]] for p, f in summary["peak_frames"].items()]


def fmt(x: float | None) -> str:
    return "    -" if x is None else f"{x:5.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    part = ap.add_mutually_exclusive_group()
    part.add_argument("--part", choices=tuple(PARTS), default="held-out", help="library part")
    part.add_argument("--only", nargs="+", choices=PERFORMANCE_NAMES, help="these performances")
    ap.add_argument("--seed", type=int, default=0, help="dataset seed (head motion, noise)")
    ap.add_argument("--coarse", action="store_true", help="coarse datasets (24 frames)")
    ap.add_argument("--root", type=Path, default=Path("data/library"), help="dataset parent")
    ap.add_argument("-c", "--config", action="append", default=[], help="extra config file")
    ap.add_argument("--set", action="append", default=[], dest="sets", help="config override")
    ap.add_argument("--results", type=Path, default=RESULTS_DIR, help="where the JSON goes")
    args = ap.parse_args()
    names = args.only or PARTS[args.part]

    rows: list[list[Any]] = []
    inverted: list[list[Any]] = []
    walls: dict[str, float] = {}
    for name in names:
        dataset = args.root / dataset_name(name, args.seed, coarse=args.coarse)
        print(f"{name}: physanim run on {dataset} ...", flush=True)
        walls[name] = run_pipeline(dataset, args.config, args.sets)
        store = StageStore(dataset / "runs" / "store.zarr", create=False)
        summary = dict(store.open("evaluate").attrs)["summary"]
        rows += peak_rows(name, summary)
        inverted += inverted_rows(name, summary)

    regions = list(dict.fromkeys(r[3] for r in rows))
    print(f"\nrelative displacement error at each peak, kinematic / FEM (seed {args.seed}"
          f"{', coarse' if args.coarse else ''})")  # fmt: skip
    print(f"{'performance':<10s} {'peak':<13s} {'frame':>5s}  "
          + "  ".join(f"{r:>13s}" for r in regions))  # fmt: skip
    for key in dict.fromkeys((r[0], r[1], r[2]) for r in rows):
        cells = {r[3]: (r[4], r[5]) for r in rows if (r[0], r[1], r[2]) == key}
        line = "  ".join(f"{fmt(cells[r][0])} / {fmt(cells[r][1])}" for r in regions)
        print(f"{key[0]:<10s} {key[1]:<13s} {key[2]:5d}  {line}")
    print("\ntets turned inside out at each peak: " + ", ".join(
        f"{name} {peak} {count}" for name, peak, _, count in inverted))  # fmt: skip

    overall = [r for r in rows if r[3] == "overall"]

    def mean(col: int) -> float | None:
        values = [r[col] for r in overall if r[col] is not None]
        return sum(values) / len(values) if values else None

    record(
        "bench_library",
        [
            Table(
                f"relative displacement error per peak and region ({len(names)} performances, "
                f"seed {args.seed}, {'coarse' if args.coarse else 'full'})",
                COLUMNS,
                rows,
                reference="the dataset's ground truth (evaluate stage)",
            ),
            Table("tets turned inside out at each peak", INVERTED_COLUMNS, inverted),
            Table("pipeline runs", ["performance", "wall_s"], [[n, walls[n]] for n in names]),
        ],
        **describe(__doc__, "bench_library"),
        headline={"kinematic_mean_overall": mean(4), "fem_mean_overall": mean(5)},
        results_dir=args.results,
    )


if __name__ == "__main__":
    main()
