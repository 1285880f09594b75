"""The product's core gesture, timed: a material edit of the demo, back with its report.

Runs the README's command ``physanim run -p face --dataset demo -c configs/models/model2.yaml``
(what ``make pipeline CONFIG=configs/models/model2.yaml`` runs) after the default run, with one
material value nudged each time (cphs_R's E by 1e-4 kPa steps) so materials, simulate,
evaluate and render run again while ingest .. tetra stay cached; side by side, the same edit
with the settings before issue #20's last round (step doubling, every panel kept as a PNG).
Prints each run's wall time and its stages' times, then medians; "the rest" is the wall time
beyond the stages' critical path (materials, simulate, then the longer of evaluate and render,
which run side by side): the CLI, Prefect and the report.

Run: .venv/bin/python benchmarks/bench_edit.py [--repeats 3]
One warm-up edit first: it starts Prefect's shared server if it is not running (a later edit
finds it, as an edit within ``PHYSANIM_PREFECT_IDLE_S`` of another run does). The edits stay in
data/demo's store like any other (``physanim clean`` drops them); at the end the default run is
made the latest again, so the report shows it.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

from results import Table, describe, record  # benchmarks/results.py, beside this script

ROOT = Path(__file__).resolve().parents[1]
EDIT = ["-c", "configs/models/model2.yaml"]
STAGES = ("materials", "simulate", "evaluate", "render")
MODES = {
    "default": [],
    "reference (doubling, all PNGs)": [
        "--set",
        "simulate.error_estimate=doubling",
        "--set",
        "render.png_frames=all",
    ],
}


def edit(nudge: int, extra: list[str]) -> tuple[float, dict[str, float]]:
    """Wall time (s) of one edit and its stages' own times (s)."""
    cmd = [sys.executable, "-m", "cli", "run", "-p", "face", "--dataset", "demo", *EDIT]
    cmd += ["--set", f"materials.model.regions.cphs_R.E_kPa={205.6 + 1e-4 * nudge:.4f}", *extra]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"edit failed ({done.returncode}):\n{done.stdout[-2000:]}{done.stderr}")
    ran = dict(re.findall(r"^(\w+): ran in ([\d.]+) s", done.stdout + done.stderr, re.M))
    return wall, {s: float(ran[s]) for s in STAGES if s in ran}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    default = [sys.executable, "-m", "cli", "run", "-p", "face", "--dataset", "demo"]
    subprocess.run(default, cwd=ROOT, check=True, capture_output=True)
    nudge = int(time.time()) % 10_000 * 10  # fresh keys on every run of this script
    edit(nudge, [])  # warm-up: Prefect's server, the OS file cache
    results: dict[str, list[tuple[float, dict[str, float]]]] = {m: [] for m in MODES}
    for i in range(args.repeats):
        for mode, extra in MODES.items():  # the modes take turns
            nudge += 1
            wall, stages = edit(nudge, extra)
            results[mode].append((wall, stages))
            shown = ", ".join(f"{s} {t:.1f}" for s, t in stages.items())
            print(f"{mode:32s} run {i + 1}: {wall:5.1f} s wall ({shown})", flush=True)
    print(f"\n{'material edit (medians of ' + str(args.repeats) + ')':32s} {'wall s':>7s}", end="")
    print("".join(f" {s:>9s}" for s in STAGES), f" {'the rest':>8s}")
    rows = []
    for mode, runs in results.items():
        wall = statistics.median(w for w, _ in runs)
        per = [statistics.median(st.get(s, 0.0) for _, st in runs) for s in STAGES]
        # evaluate and render run side by side after simulate (render 10, evaluate 16)
        rest = wall - (per[0] + per[1] + max(per[2], per[3]))
        print(f"{mode:32s} {wall:7.1f}" + "".join(f" {t:9.1f}" for t in per) + f" {rest:9.1f}")
        rows.append([mode, wall, [w for w, _ in runs], *per, rest])
    subprocess.run(default, cwd=ROOT, check=True, capture_output=True)  # the latest again
    columns = ["mode", "wall_s", "runs_s", *(f"{s}_s" for s in STAGES), "rest_s"]
    record(
        "bench_edit",
        [
            Table(
                f"material edit (medians of {args.repeats})",
                columns,
                rows,
                reference="the settings before issue #20's last round",
            )
        ],  # fmt: skip
        **describe(__doc__, "bench_edit"),
        headline={"edit_s": rows[0][1], "reference_s": rows[1][1]},
    )


if __name__ == "__main__":
    main()
