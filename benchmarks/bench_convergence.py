"""Mesh convergence of the demo face: the figures and the cost at each tet size.

For each mesh (uniform ``tetra.edge_length_m`` of 4, 3, 2.5, 2 and 1.5 mm, and the regional
refinement of ``configs/meshes/refined.yaml``) it runs tetra, materials, actuate, simulate and
evaluate of the demo at the default (uniform) material, then materials, simulate and evaluate
with models 2 and 3, each stage in its own process (``physanim run --local --only``), and
prints per mesh: nodes, tets, the Newmark factor's entries, peak memory and wall time of the
stages, factorisation and per-step solve time of simulate, the FEM's relative displacement
error at the jaw-drop and smile peaks, its lip gap there and the philtrum peaks of models 2
and 3 (right side, the edited one). Then the growth exponents of time and memory against nodes
(least squares in log-log over the uniform meshes) and the relative change of each figure
between the two finest uniform meshes. The skin surface fed to fTetWild is the same 2.5 mm
remesh at every size, so the meshes discretise one geometry.

Run: .venv/bin/python benchmarks/bench_convergence.py [--sizes-mm 4 3 2.5 2 1.5] [--no-refined]
     [--plot docs/convergence.png]; ``--pooled 3`` measures nothing and prints the comparisons
     over the last three recorded runs' meshes together.
Uses data/demo's store (each mesh is cached there like any run; ``physanim clean`` drops them).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
from results import RESULTS_DIR, Table, describe, load, record  # benchmarks/results.py

ROOT = Path(__file__).resolve().parents[1]
PHYSANIM = [sys.executable, "-m", "cli"]  # the physanim command of this interpreter
MODELS = {"uniform": [], "model2": ["-c", "configs/models/model2.yaml"],
          "model3": ["-c", "configs/models/model3.yaml"]}  # fmt: skip
REFINED = ["-c", "configs/meshes/refined.yaml"]
#: the figures compared between meshes: (name, where in the evaluate summaries)
FIGURES = ("fidelity_jaw", "fidelity_smile", "lip_gap_jaw_mm", "lip_gap_smile_mm",
           "philtrum_m2_mm", "philtrum_m3_mm", "philtrum_m3_over_m2")  # fmt: skip


def worker(stage: str, args: list[str]) -> None:
    """Run one stage in this process (the CLI's ``run --local --only``) and print a last
    JSON line: its peak resident memory."""
    import resource

    from cli.app import main

    sys.argv = ["physanim", "run", "--local", "--only", stage, *args]
    try:
        main()
    except SystemExit as exc:
        if exc.code:
            raise
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"peak_rss_gb": peak_kb / 2**20}))


def run_stage(stage: str, args: list[str]) -> dict[str, Any]:
    """One stage in a fresh process: its wall time (s) and key, peak memory."""
    cmd = [sys.executable, __file__, "--worker", stage, "--", *args]
    from cli import PROCESS_ENV  # the command's own settings: this module imports numpy first

    env = {**PROCESS_ENV, **os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env, check=False)
    if done.returncode:
        raise RuntimeError(f"{stage} {args} failed:\n{done.stdout[-2000:]}{done.stderr[-3000:]}")
    log = done.stdout + done.stderr
    found = re.search(rf"^{stage}: (?:ran in ([\d.]+) s|cached) \((\w+)\)", log, re.M)
    if found is None:
        raise RuntimeError(f"{stage}: no 'ran in' line in\n{log[-2000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    out.update(seconds=float(found.group(1) or "nan"), key=found.group(2))
    return out


def show(stage: str, key: str) -> dict[str, Any]:
    """The provenance JSON of a stage output (``physanim show``)."""
    cmd = [*PHYSANIM, "show", stage, "--dataset", "demo", "--key", key]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def measure(label: str, mesh_args: list[str]) -> dict[str, Any]:
    """All stages of one mesh, the uniform material and models 2 and 3: one result row."""
    base = ["--dataset", "demo", *mesh_args]
    row: dict[str, Any] = {"mesh": label}
    for stage in ("tetra", "materials", "actuate", "simulate", "evaluate"):
        # tetra forced: a fresh fTetWild mesh and its time, not a cached one
        row[stage] = run_stage(stage, [*base, "--force", "tetra"] if stage == "tetra" else base)
        print(f"  {label} {stage}: {row[stage]['seconds']:.1f} s, "
              f"{row[stage]['peak_rss_gb']:.2f} GB", flush=True)  # fmt: skip
    for model in ("model2", "model3"):
        for stage in ("materials", "simulate", "evaluate"):
            row[f"{model}_{stage}"] = run_stage(stage, [*base, *MODELS[model]])
    tetra = show("tetra", row["tetra"]["key"])["summary"]
    sim = show("simulate", row["simulate"]["key"])["summary"]
    ev = show("evaluate", row["evaluate"]["key"])["summary"]
    ev2 = show("evaluate", row["model2_evaluate"]["key"])["summary"]
    ev3 = show("evaluate", row["model3_evaluate"]["key"])["summary"]
    fid, gap = ev["fidelity"]["fem"], ev["lip_gap_mm"]["fem"]
    m2, m3 = ev2["philtrum_peak_mm"]["right"], ev3["philtrum_peak_mm"]["right"]
    row.update(
        nodes=tetra["n_nodes"], tets=tetra["n_tets"], min_dihedral_deg=tetra["min_dihedral_deg"],
        regions=tetra.get("regions"), factor_entries=sim["factor_entries"],
        factorization_s=sim["seconds"]["factorization"],
        step_ms=1e3 * sim["seconds"]["stepping"] / max(sim["steps"], 1),
        inverted_tets=sim["inverted_tets"],
        fidelity_jaw=fid["jaw_open"]["overall"], fidelity_smile=fid["smile"]["overall"],
        lip_gap_jaw_mm=gap["jaw_open"], lip_gap_smile_mm=gap["smile"],
        philtrum_m2_mm=m2, philtrum_m3_mm=m3, philtrum_m3_over_m2=m3 / m2,
    )  # fmt: skip
    return row


def exponent(x: list[float], y: list[float]) -> float:
    """Least-squares slope of log y against log x."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Figures against tet size (relative to the finest uniform mesh) and cost against nodes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    uniform = [r for r in rows if r["h_mm"] is not None]
    finest = min(uniform, key=lambda r: r["h_mm"])
    base = means(rows)[finest["h_mm"]]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    h = [r["h_mm"] for r in uniform]
    for name in FIGURES:
        line = a.plot(h, [100 * (r[name] / base[name] - 1) for r in uniform], "o", label=name)
        for r in rows:  # a graded mesh at the uniform size of as many nodes
            if r["h_mm"] is None:
                at = finest["h_mm"] * np.cbrt(finest["nodes"] / r["nodes"])
                a.plot(at, 100 * (r[name] / base[name] - 1), "x", color=line[0].get_color())
    a.axhspan(-2, 2, color="green", alpha=0.1)
    a.set(
        xlabel="uniform tet edge length (mm); x: the refined mesh at its nodes' size",
        ylabel=f"change from the mean at {finest['h_mm']:g} mm (%)",
        title="figures against mesh size",
    )
    a.invert_xaxis()
    a.legend(fontsize=7)
    n = [r["nodes"] for r in rows]
    for key, label in (
        ("simulate_s", "simulate wall (s)"),
        ("actuate_s", "actuate wall (s)"),
        ("tetra_s", "tetra wall (s)"),
        ("simulate_peak_gb", "simulate peak (GB)"),
    ):
        b.loglog(n, [r[key] for r in rows], "o", label=label)  # fmt: skip
    b.set(xlabel="nodes", title="cost against nodes (2 cores)")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def means(rows: list[dict[str, Any]]) -> dict[float, dict[str, float]]:
    """Uniform tet size (mm) -> each figure's mean over that size's meshes."""
    sizes = sorted({r["h_mm"] for r in rows if r["h_mm"] is not None})
    return {
        h: {f: float(np.mean([r[f] for r in rows if r["h_mm"] == h])) for f in FIGURES}
        for h in sizes
    }


def spread(rows: list[dict[str, Any]], h: float) -> dict[str, float]:
    """Each figure's spread over the meshes of uniform size ``h`` mm: (max - min) / mean, %
    (fTetWild's run-to-run variation at one size; 0 for a single mesh)."""
    at = [r for r in rows if r["h_mm"] == h]
    return {f: 100 * float(np.ptp([r[f] for r in at]) / abs(np.mean([r[f] for r in at])))
            for f in FIGURES}  # fmt: skip


def tables_of(rows: list[dict[str, Any]]) -> list[Table]:
    """The result tables: every mesh; fTetWild's spread at sizes meshed more than once; the
    change between the two finest sizes (means over their meshes); growth exponents; tets per
    region; the refined mesh against the 2 mm meshes."""
    cost = ("nodes", "tets", "min_dihedral_deg", "factor_entries", "tetra_s", "actuate_s",
            "simulate_s", "factorization_s", "step_ms", "simulate_peak_gb", "actuate_peak_gb",
            "inverted_tets")  # fmt: skip
    tables = [Table("meshes", ["mesh", *cost, *FIGURES], [[r["mesh"], *(r[c] for c in cost),
                    *(r[f] for f in FIGURES)] for r in rows])]  # fmt: skip
    tables += spread_and_change(rows)
    sizes = sorted(means(rows))
    if len(sizes) >= 2:
        first = [next(r for r in rows if r["h_mm"] == h) for h in sizes]  # one mesh a size
        nodes = [r["nodes"] for r in first]
        growth = [[c, exponent(nodes, [r[c] for r in first])] for c in
                  ("factor_entries", "factorization_s", "step_ms", "simulate_s", "actuate_s",
                   "tetra_s", "simulate_peak_gb", "actuate_peak_gb")]  # fmt: skip
        tables.append(Table("growth against nodes", ["cost", "exponent"], growth,
                            notes="cost ~ nodes^exponent over the uniform meshes"))  # fmt: skip
    regions = [[r["mesh"], name, *q.values()] for r in rows for name, q in r["regions"].items()]
    tables.append(Table("tets per region", ["mesh", "region", "tets", "median_edge_mm",
                                            "min_dihedral_deg"], regions))  # fmt: skip
    return tables + refined_against_2mm(rows)


def spread_and_change(rows: list[dict[str, Any]]) -> list[Table]:
    """fTetWild's spread at the sizes meshed more than once, and the change of each figure
    between the two finest sizes (means over their meshes)."""
    tables, mean = [], means(rows)
    repeated = [h for h in mean if sum(r["h_mm"] == h for r in rows) > 1]
    if repeated:
        tables.append(Table("spread between fTetWild meshes of one size",
                            ["figure", *(f"{h:g} mm spread_pct" for h in repeated)],
                            [[f, *(spread(rows, h)[f] for h in repeated)] for f in FIGURES],
                            notes="(max - min) / mean over the meshes of that size"))  # fmt: skip
    sizes = sorted(mean)
    if len(sizes) >= 2:
        fine, next_ = sizes[0], sizes[1]
        change = [[f, 100 * abs(mean[fine][f] / mean[next_][f] - 1), spread(rows, fine)[f]]
                  for f in FIGURES]  # fmt: skip
        tables.append(Table(f"change {next_:g} mm -> {fine:g} mm", ["figure", "change_pct",
                            f"spread_{fine:g}mm_pct"], change,
                            notes="convergence target: below 2 %; means over each size's "
                            "meshes"))  # fmt: skip
    return tables


def refined_against_2mm(rows: list[dict[str, Any]]) -> list[Table]:
    """Each graded mesh's figures against the mean of the 2 mm meshes (the issue's)."""
    mean = means(rows)
    if 2.0 not in mean:
        return []
    ref = [r for r in rows if r["h_mm"] == 2.0]
    return [Table(f"{refined['mesh']} against 2 mm", ["figure", "change_pct", "spread_2mm_pct"],
                  [[f, 100 * abs(refined[f] / mean[2.0][f] - 1), spread(rows, 2.0)[f]]
                   for f in FIGURES]
                  + [["nodes_ratio", refined["nodes"] / float(np.mean([r["nodes"] for r in ref])),
                      None]]) for refined in rows if refined["h_mm"] is None]  # fmt: skip


def pooled(n_runs: int) -> None:
    """Print the comparisons over the meshes of the last ``n_runs`` recorded runs together
    (each run meshes every size afresh: more meshes a size than one run affords), the graded
    meshes pooled as one."""
    runs = load(RESULTS_DIR / "bench_convergence.json")["runs"][-n_runs:]
    rows = []
    for run in runs:
        table = next(t for t in run["tables"] if t["name"] == "meshes")
        for cells in table["rows"]:
            row = dict(zip(table["columns"], cells, strict=True))
            size = row["mesh"].split(" mm")[0]
            row["h_mm"] = float(size) if size.replace(".", "").isdigit() else None
            rows.append(row)
    graded = [r for r in rows if r["h_mm"] is None]
    if graded:
        rows = [r for r in rows if r["h_mm"] is not None]
        rows.append({"mesh": f"refined ({len(graded)} meshes)", "h_mm": None,
                     "nodes": float(np.mean([r["nodes"] for r in graded])),
                     **{f: float(np.mean([r[f] for r in graded])) for f in FIGURES}})  # fmt: skip
    dates = f"{runs[0]['date']} to {runs[-1]['date']}"
    print(
        f"pooled over {len(runs)} runs ({dates}): "
        + ", ".join(f"{h:g} mm x{sum(r['h_mm'] == h for r in rows)}" for h in sorted(means(rows)))
    )
    for t in spread_and_change(rows) + refined_against_2mm(rows):
        print(f"\n{t.name}\n" + "\n".join(str(row) for row in [t.columns, *t.rows]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes-mm", type=float, nargs="+", default=[4, 3, 2.5, 2, 1.5])
    parser.add_argument("--repeat-mm", type=float, nargs="*", default=[2.0],
                        help="sizes meshed --repeats times (fTetWild's spread)")  # fmt: skip
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-refined", action="store_true", help="skip the regional mesh")
    parser.add_argument("--plot", type=Path, default=ROOT / "docs" / "convergence.png")
    parser.add_argument("--label", default="uniform 4-1.5 mm, 2 mm three times, refined")
    parser.add_argument("--pooled", type=int, metavar="RUNS",
                        help="measure nothing: print the comparisons over the meshes of the "
                        "last RUNS recorded runs together")  # fmt: skip
    args = parser.parse_args()
    if args.pooled:
        pooled(args.pooled)
        return
    meshes = []
    for h in sorted(args.sizes_mm, reverse=True):
        n = args.repeats if h in args.repeat_mm else 1
        meshes += [(f"{h:g} mm" + (f" #{i + 1}" if i else ""), [f"--set=tetra.edge_length_m="
                   f"{h / 1e3:g}"], h) for i in range(n)]  # fmt: skip
    if not args.no_refined:
        meshes.insert(len(meshes) - 1 if len(meshes) > 1 else 0, ("refined", REFINED, None))
    rows = []
    for label, mesh_args, h in meshes:
        print(f"== {label}", flush=True)
        row = measure(label, mesh_args)
        row.update(h_mm=h, tetra_s=row["tetra"]["seconds"], actuate_s=row["actuate"]["seconds"],
                   simulate_s=row["simulate"]["seconds"],
                   simulate_peak_gb=row["simulate"]["peak_rss_gb"],
                   actuate_peak_gb=row["actuate"]["peak_rss_gb"])  # fmt: skip
        rows.append(row)
        print({k: row[k] for k in ("nodes", "simulate_s", *FIGURES)}, flush=True)
    tables = tables_of(rows)
    for t in tables:
        print(f"\n{t.name}\n" + "\n".join(str(row) for row in [t.columns, *t.rows]))
    plot(rows, args.plot)
    record("bench_convergence", tables, label=args.label, args=sys.argv[1:],
           **describe(__doc__, "bench_convergence"))  # fmt: skip


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--worker":
        worker(sys.argv[2], sys.argv[4:] if sys.argv[3:4] == ["--"] else sys.argv[3:])
    else:
        main()
