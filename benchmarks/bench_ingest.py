"""Ingest throughput (frames/s) per source on the demo dataset.

Usage: .venv/bin/python benchmarks/bench_ingest.py [DATASET_DIR] [--frames N]
Generates a demo of N frames (default 30) into a temp dir when no dataset is given.
The RGBD folder (PNG decode only) is the baseline the other sources are compared with;
the bag is replayed by Open3D in real time, so it cannot exceed the recording's fps.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from results import Table, describe, record  # benchmarks/results.py, beside this script

from physanim.capture.demo import generate_demo
from physanim.capture.ingest import load_capture
from physanim.capture.params import IngestParams


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("dataset", nargs="?", type=Path)
    ap.add_argument("--frames", type=int, default=30)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        dataset = args.dataset
        if dataset is None:
            t0 = time.perf_counter()
            dataset = generate_demo(Path(tmp) / "demo", n_frames=args.frames)
            print(f"demo: {args.frames} frames generated in {time.perf_counter() - t0:.1f} s")
        rows = []
        for source, extra in (
            ("rgbd", {}),
            ("bag", {}),
            ("stereo", {}),
            ("stereo", {"wls": True}),
        ):
            t0 = time.perf_counter()
            cap = load_capture(dataset, IngestParams(source=source, **extra))
            dt = time.perf_counter() - t0
            label = source + (" +WLS" if extra else "")
            rows.append((label, cap.n_frames, dt, cap.n_frames / dt))
        base = rows[0][3]
        print(f"{'source':<12}{'frames':>8}{'seconds':>10}{'frames/s':>10}{'vs rgbd':>9}")
        for label, n, dt, fps in rows:
            print(f"{label:<12}{n:>8}{dt:>10.2f}{fps:>10.1f}{fps / base:>9.2f}")
    table = [[label, n, dt, fps, fps / base] for label, n, dt, fps in rows]
    columns = ["source", "frames", "wall_s", "frames_per_s", "ratio_to_rgbd"]
    by_source = {r[0]: r[3] for r in table}
    record(
        "bench_ingest",
        [Table("ingest throughput per source", columns, table, reference="the RGBD folder")],
        **describe(__doc__, "bench_ingest"),
        headline={f"{s}_frames_per_s": by_source[s] for s in ("rgbd", "bag", "stereo")},
    )


if __name__ == "__main__":
    main()
