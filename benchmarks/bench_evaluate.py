"""Benchmark the ``evaluate`` stage on the demo: the truth comparison with Open3D's closest-point
search (``evaluate.closest_points: bvh``, the default) next to the seed's exact grid search
(``grid``, the reference and the code before issue #20), in this process, medians of 3 runs.

Each run times what the stage computes: reading its inputs from the store, loading the ground
truth and ``evaluate_face`` (the write of the output is left out). Printed: seconds per path and
the largest relative difference between the two paths' summary figures (motion fidelity per
region at the jaw-drop and smile peaks, the lip gaps there, the RMS surface distances and the
mean symmetry costs).

Run: .venv/bin/python benchmarks/bench_evaluate.py [--repeats 3]
The upstream outputs are the demo pipeline's own (default config), computed into data/demo first
when the store lacks them (several minutes, once).
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np
from results import Table, describe, record  # benchmarks/results.py, beside this script

from flows.dags import FACE
from physanim.config import load_config
from physanim.evaluate.face import EvaluateParams, FaceEvaluation, evaluate_face
from physanim.evaluate.truth import load_truth
from physanim.pipeline import stage_inputs
from physanim.pipeline.progress import rich_progress
from physanim.pipeline.spec import dataset_overrides
from tasks.evaluate import face_run


def demo_evaluate(config: Any) -> tuple[EvaluateParams, Any]:
    """The evaluate params of the demo and a function running the stage's computation."""
    with rich_progress() as progress:
        inputs = stage_inputs(FACE, config, "evaluate", progress)
    params = config.section("evaluate", EvaluateParams)

    def evaluate(p: EvaluateParams) -> tuple[FaceEvaluation, dict[str, Any]]:
        run = face_run(**inputs)
        truth = load_truth(config.dataset.path / p.truth, run.displacements.shape[0])
        return evaluate_face(run, truth, p)

    return params, evaluate


def figures(ev: FaceEvaluation) -> dict[str, float]:
    """The summary figures compared between the paths, unrounded."""
    assert ev.peak_frames is not None and ev.regions is not None
    out: dict[str, float] = {}
    for label in ("fem", "kinematic"):
        fid = getattr(ev, f"fidelity_{label}")
        gap = getattr(ev, f"lip_gap_{label}")
        for peak, f in ev.peak_frames.items():
            out[f"fidelity {label} {peak} overall"] = float(fid.overall[f])
            for i, region in enumerate(ev.regions):
                out[f"fidelity {label} {peak} {region}"] = float(fid.regions[f, i])
            out[f"lip gap {label} {peak}"] = float(gap[f])
        err = getattr(ev, f"error_{label}")
        out[f"surface distance {label}"] = float(np.sqrt(np.mean(err**2)))
        out[f"symmetry cost {label}"] = float(np.mean(getattr(ev, label).cost[1:]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3, help="runs per path")
    args = ap.parse_args()
    config, _ = load_config(FACE.config_model(), [FACE.default_config], dataset_overrides("demo"))
    params, evaluate = demo_evaluate(config)
    import open3d  # noqa: F401  (the flows load it in the main thread before any stage)

    paths = {
        "grid (seed's exact search, reference)": params.model_copy(
            update={"closest_points": "grid"}
        ),
        "bvh (Open3D, default)": params.model_copy(update={"closest_points": "bvh"}),
    }
    seconds, found = {}, {}
    for name, p in paths.items():
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            ev, _ = evaluate(p)
            times.append(time.perf_counter() - t0)
        seconds[name] = statistics.median(times)
        found[name] = figures(ev)
    print(f"{'evaluate on the demo':40s} {'median s':>9s}")
    for name, s in seconds.items():
        print(f"{name:40s} {s:9.2f}")
    ref, new = found.values()
    undefined = [k for k in ref if not np.isfinite(ref[k])]
    if any(np.isfinite(new[k]) for k in undefined):
        raise SystemExit("the paths disagree on which figures are undefined (no true motion)")
    rel = {k: abs(new[k] - ref[k]) / max(abs(ref[k]), 1e-12) for k in ref if k not in undefined}
    worst = max(rel, key=rel.__getitem__)
    speed_up = seconds[next(iter(paths))] / seconds[list(paths)[1]]
    print(
        f"speed-up {speed_up:.1f}x; {len(rel)} summary figures ({len(undefined)} undefined in "
        f"both), max relative difference {rel[worst]:.2e} ({worst})"
    )
    record(
        "bench_evaluate",
        [
            Table(
                f"evaluate on the demo, medians of {args.repeats}",
                ["path", "median_s"],
                [[name, s] for name, s in seconds.items()],
                notes=f"speed-up {speed_up:.1f}x; {len(rel)} summary figures ({len(undefined)} "
                f"undefined in both), max relative difference {rel[worst]:.2e} ({worst})",
            )
        ],  # fmt: skip
        **describe(__doc__, "bench_evaluate"),
        headline={
            "bvh_s": seconds[list(paths)[1]],
            "grid_s": seconds[next(iter(paths))],
            "max_rel_diff": rel[worst],
        },  # fmt: skip
    )


if __name__ == "__main__":
    main()
