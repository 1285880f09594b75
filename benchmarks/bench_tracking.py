"""Markers-backend tracking speed at 640x480 (target >= 30 frames/s).

Prints frames/s of the full 2D tracker (labelling, LK, ROI re-detection, assignment) next
to a baseline measured in the same process: full-frame dot detection alone per frame.
Frames are synthetic: 36 anti-aliased dots on a shaded, noisy skin background, moving.

Run: .venv/bin/python benchmarks/bench_tracking.py
"""

from __future__ import annotations

import time

import cv2
import numpy as np
from results import Table, describe, record  # benchmarks/results.py, beside this script

from physanim.tracking.detect import detect_markers
from physanim.tracking.params import TrackParams
from physanim.tracking.track import track_markers_2d


def frames(n: int = 60, seed: int = 0) -> tuple[list[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(6), np.arange(6)), -1).reshape(-1, 2) * 30.0
    template = grid + rng.uniform(-6, 6, grid.shape) - grid.mean(axis=0)
    vv, uu = np.mgrid[0:480, 0:640]
    shade = 0.75 + 0.25 * np.sin(uu / 37.0) * np.cos(vv / 53.0)
    base = np.array([200.0, 150.0, 120.0]) * shade[..., None]
    out = []
    for t in range(n):
        img = np.clip(base + rng.normal(0, 2.0, base.shape), 0, 255).astype(np.uint8)
        centre = template * 1.8 + [320 + 20 * np.sin(t / 9), 240 + 10 * np.cos(t / 7)]
        for u, v in centre:
            cv2.circle(img, (int(u * 16), int(v * 16)), 40, (56, 92, 107), -1, cv2.LINE_AA, 4)
        out.append(img)
    return out, template


def main() -> None:
    imgs, template = frames()
    params = TrackParams()
    t0 = time.perf_counter()
    for img in imgs:
        detect_markers(img, params)
    base = len(imgs) / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    uv, conf = track_markers_2d(imgs, template, params)
    fps = len(imgs) / (time.perf_counter() - t0)
    print(f"tracking (markers, 640x480): {fps:7.1f} frames/s  (target >= 30)")
    print(f"baseline full-frame detection only: {base:7.1f} frames/s")
    print(f"markers tracked: {conf.mean():.3f} of {conf.size} marker-frames")
    rows = [["2D tracker (markers)", fps], ["full-frame detection only (baseline)", base]]
    record(
        "bench_tracking",
        [
            Table(
                f"marker tracking at 640x480, {len(imgs)} synthetic frames",
                ["tracker", "frames_per_s"],
                rows,
                notes=f"markers tracked: {conf.mean():.3f} of {conf.size} marker-frames",
            )
        ],
        **describe(__doc__, "bench_tracking"),
        headline={"tracking_frames_per_s": fps},
    )


if __name__ == "__main__":
    main()
