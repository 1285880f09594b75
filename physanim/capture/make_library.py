"""Generate the performance library's datasets (``physanim.capture.library``) in bulk::

    python -m physanim.capture.make_library [--out data/library] [--coarse] [--only NAME ...]
        [--seeds 0 1 2] [--markerless] [--force] [--workers N]

Apart from the library itself because it renders them (``physanim.capture.demo``, which reads
the library's performances).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from physanim.capture.demo import generate_demo
from physanim.capture.ingest import has_recording
from physanim.capture.library import (
    COARSE_FRAMES,
    DEFAULT_SEEDS,
    FULL_FRAMES,
    HELD_OUT,
    PERFORMANCE_NAMES,
    TUNING,
    dataset_name,
    library_params,
)
from physanim.capture.params import DemoParams


def generate_library(
    out: Path,
    names: Sequence[str] = PERFORMANCE_NAMES,
    seeds: Sequence[int] = DEFAULT_SEEDS,
    *,
    coarse: bool = False,
    markers: bool = True,
    force: bool = False,
    workers: int | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Generate one dataset folder ``out/<dataset_name>`` per performance and seed (those
    already recorded are kept unless ``force``); ``log`` gets one line per dataset.
    Returns the folders."""
    jobs = [dataset_name(n, s, coarse=coarse, markers=markers) for n in names for s in seeds]
    folders = []
    for i, job in enumerate(jobs, 1):
        folder = Path(out) / job
        folders.append(folder)
        if has_recording(folder) and not force:
            log(f"[{i}/{len(jobs)}] {folder}: present (kept)")
            continue
        params = library_params(job, DemoParams())
        assert params is not None
        start = time.perf_counter()
        generate_demo(folder, params=params, workers=workers)
        took = time.perf_counter() - start
        log(f"[{i}/{len(jobs)}] {folder}: {params.n_frames} frames in {took:.0f} s")
    return folders


def main(argv: Sequence[str] | None = None) -> None:
    """Command line: see the module docstring."""
    ap = argparse.ArgumentParser(
        prog="python -m physanim.capture.make_library",
        description="Generate the performance library's datasets (one folder per performance "
        "and seed). Tuning part: " + ", ".join(TUNING) + "; held out: " + ", ".join(HELD_OUT),
    )
    ap.add_argument("--out", type=Path, default=Path("data/library"), help="parent folder")
    ap.add_argument(
        "--coarse", action="store_true", help=f"{COARSE_FRAMES} frames (else {FULL_FRAMES})"
    )
    part = ap.add_mutually_exclusive_group()
    part.add_argument("--only", nargs="+", choices=PERFORMANCE_NAMES, help="these performances")
    part.add_argument("--part", choices=("tuning", "held-out"), help="one part of the library")
    ap.add_argument("--seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS), help="seeds")
    ap.add_argument("--markerless", action="store_true", help="no painted marker dots")
    ap.add_argument("--force", action="store_true", help="regenerate datasets already there")
    ap.add_argument("--workers", type=int, default=None, help="render processes (default: cores)")
    args = ap.parse_args(argv)
    names = (
        args.only or {"tuning": TUNING, "held-out": HELD_OUT, None: PERFORMANCE_NAMES}[args.part]
    )
    generate_library(
        args.out,
        names,
        args.seeds,
        coarse=args.coarse,
        markers=not args.markerless,
        force=args.force,
        workers=args.workers,
    )


if __name__ == "__main__":
    main()
