"""Benchmark face rendering per frame on the real face000 scan (44k vertices, 87k triangles):
the project's rasteriser (default: compiled z-buffer and shader, frames over all cores; and
on one thread) vs VTK (Mesa llvmpipe without a GPU) in an isolated worker (the reference, and
the default before 2026-12-06) and in-process,
and video encoding: VP9 .mp4 / VP8 .webm (browser-playable) vs mp4v (baseline, not
playable in browsers), all in this process.

Run: .venv/bin/python benchmarks/bench_render.py [--frames 40] [--width 480 --height 640]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from results import Table, describe, record  # benchmarks/results.py, beside this script

from physanim.capture.actor import build_actor
from physanim.render.colours import ColourMap
from physanim.render.face import render_sequence
from physanim.render.panel import panel, write_mp4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=640)
    args = ap.parse_args()
    actor = build_actor()
    v = actor.vertices
    t = np.linspace(0.0, 1.0, args.frames)
    bump = 0.004 * np.exp(-((v[:, 0] - 0.03) ** 2 + (v[:, 1] + 0.05) ** 2) / 8e-4)
    seq = v[None] + np.sin(np.pi * t)[:, None, None] * np.c_[0 * bump, bump, bump][None]
    disp = 1e3 * np.linalg.norm(seq - v[None], axis=2)
    size = (args.width, args.height)
    cmap = ColourMap("displacement (mm)", (0.0, 4.0))
    print(
        f"{args.frames} frames, {size[0]}x{size[1]} px, {len(v)} vertices, {len(actor.faces)} tris"
    )
    print(f"{'variant':34s} {'s/frame':>8s} {'total s':>8s}")
    frames = {}
    rows = []  # (variant, s per frame, total s), recorded at the end
    for name, kw in [
        ("project rasteriser (default)", dict(backend="raster")),
        ("project rasteriser, one thread", dict(backend="raster", threads=1)),
        ("vtk, isolated worker (reference)", dict(backend="vtk")),
        ("vtk, in-process", dict(backend="vtk", isolate=False)),
    ]:
        for label, sc in [("skin", None), ("colour map", disp)]:
            t0 = time.perf_counter()
            out = render_sequence(
                seq,
                actor.faces,
                scalars=sc,
                colour_map=cmap if sc is not None else None,
                size=size,
                **kw,
            )
            dt = time.perf_counter() - t0
            frames[label] = out
            print(f"{name + ', ' + label:34s} {dt / args.frames:8.3f} {dt:8.2f}")
            rows.append([f"{name}, {label}", dt / args.frames, dt])
    tiles = [
        panel([frames["skin"][i]] * 2 + [frames["colour map"][i]] * 2, ["a", "b", "c", "d"])
        for i in range(args.frames)
    ]
    with tempfile.TemporaryDirectory() as tmp:
        h, w = tiles[0].shape[:2]
        for codec, suffix, ffmpeg in (
            ("vp09", ".mp4", True),  # imageio-ffmpeg's FFmpeg, realtime mode (default)
            ("vp09", ".mp4", False),  # OpenCV's FFmpeg (the fallback)
            ("VP80", ".webm", False),
            ("mp4v", ".mp4", False),
        ):
            t0 = time.perf_counter()
            write_mp4(tiles, Path(tmp) / f"{codec}{suffix}", 30.0, codecs=(codec,), ffmpeg=ffmpeg)
            dt = time.perf_counter() - t0
            via = "FFmpeg realtime" if ffmpeg else "OpenCV"
            name = f"encode {codec}{suffix} {w}x{h}, {via}"
            print(f"{name:34s} {dt / args.frames:8.3f} {dt:8.2f}")
            rows.append([name, dt / args.frames, dt])
    n_render = len(rows) - 4
    columns = ["variant", "s_per_frame", "total_s"]
    size_text = f"{size[0]}x{size[1]} px, {args.frames} frames"
    record(
        "bench_render",
        [
            Table(f"face render, {size_text}", columns, rows[:n_render]),
            Table(f"encoding {args.frames} panels of {w}x{h}", columns, rows[n_render:]),
        ],
        **describe(__doc__, "bench_render"),
        headline={
            "vtk_worker_s_per_frame": rows[0][1],
            "rasteriser_s_per_frame": rows[4][1],
            "vp9_ffmpeg_s_per_frame": rows[n_render][1],
        },
    )


if __name__ == "__main__":
    main()
