"""Dense capture on the demo: seconds per frame beside the landmark tracker's, and how well each
captured scan follows the actor's true motion.

In this process, on the demo's 90 frames (640x480): the landmark tracker (stage ``track``:
markers found, labelled, tracked, lifted to 3D and smoothed) and dense capture (stage ``dense``:
flow both ways, lifting, head pose, fill), each timed end to end from the stored ingest output.
Then the relative displacement error on the moving skin at each expression peak and region
(``physanim.evaluate.fidelity``, every scan vertex) of the kinematic scan (the scan bound to the
fitted face model, ``dense.method: kinematic``) and of the dense capture, and the RMS error of
the moving skin in mm (target: <= 0.10 relative and <= 0.5 mm RMS at every peak, issue #31).

Run: .venv/bin/python benchmarks/bench_dense.py [--dataset demo]
The upstream outputs are the pipeline's own (default config), computed first when the store
lacks them.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from results import Table, describe, record  # benchmarks/results.py, beside this script

from flows.dags import FACE
from physanim.config import load_config
from physanim.evaluate.fidelity import REGIONS, face_regions, follow_truth, motion_fidelity
from physanim.evaluate.truth import load_truth
from physanim.pipeline import stage_inputs
from physanim.pipeline.progress import rich_progress
from physanim.pipeline.spec import dataset_overrides
from physanim.tracking.dense import dense_track
from physanim.tracking.dense_params import DenseParams
from physanim.tracking.params import TrackParams
from physanim.tracking.recording import track_recording
from tasks.track import TrackStageParams


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dataset", default="demo", help="dataset name (data/<name>)")
    args = ap.parse_args()
    config, _ = load_config(
        FACE.config_model(), [FACE.default_config], dataset_overrides(args.dataset)
    )
    with rich_progress() as progress:
        inputs = stage_inputs(FACE, config, "dense", progress)
    ingest, track, align = inputs["ingest"], inputs["track"], inputs["align"]
    T = ingest.color.shape[0]
    stage = config.section("track", TrackStageParams)
    tracking = TrackParams.model_validate(
        stage.model_dump(exclude={"template", "lift", "stereo_dir"})
    )
    dataset = config.dataset.path

    t0 = time.perf_counter()
    track_recording(
        ingest.color, ingest.depth, ingest.K, float(ingest.fps), tracking, stage.lift,
        dataset / stage.template, dataset / stage.stereo_dir,
    )  # fmt: skip
    track_s = (time.perf_counter() - t0) / T

    params = config.section("dense", DenseParams)
    kinematic = np.asarray(align.kinematic[...], dtype=np.float64)
    vertices = align.scan_vertices
    t0 = time.perf_counter()
    dense = dense_track(
        ingest.color, ingest.depth, ingest.K, track.head_pose, vertices, align.scan_faces,
        params, kinematic - vertices[None],
    )  # fmt: skip
    dense_s = (time.perf_counter() - t0) / T
    print(f"landmark tracker: {track_s:.3f} s/frame; dense capture: {dense_s:.3f} s/frame")

    truth = load_truth(dataset / "ground_truth.zarr", T)
    true_u = follow_truth(vertices, truth.vertices, truth.faces).displacement
    labels = face_regions(vertices, align.landmark_positions())
    variants = {"kinematic scan": kinematic - vertices[None], "dense capture": dense.displacement}
    columns = ["peak", "frame", "captured", "overall", *REGIONS, "rms_mm"]
    rows = []
    for peak, f in truth.peak_frames().items():
        moving = (true_u[f] ** 2).sum(axis=1) > 1e-6
        for name, u in variants.items():
            fid = motion_fidelity(u[f : f + 1], true_u[f : f + 1], labels)
            rms = float(np.sqrt(((u[f] - true_u[f])[moving] ** 2).sum(axis=1).mean()) * 1e3)
            regions = [None if np.isnan(x) else float(x) for x in fid.regions[0]]
            rows.append([peak, f, name, float(fid.overall[0]), *regions, rms])
    print(f"{'peak':10s} {'captured':15s} {'overall':>8s} " + " ".join(f"{r:>9s}" for r in REGIONS))
    for r in rows:
        cells = " ".join("      n/a" if x is None else f"{x:9.3f}" for x in r[4:-1])
        print(f"{r[0]:10s} {r[2]:15s} {r[3]:8.3f} {cells}  rms {r[-1]:.2f} mm")
    record(
        "bench_dense",
        [
            Table(
                f"dense capture and landmark tracking on {args.dataset}, {T} frames",
                ["stage", "s_per_frame"],
                [["track (landmarks)", track_s], ["dense (every scan vertex)", dense_s]],
            ),
            Table(
                "relative displacement error on the moving skin at each expression peak",
                columns,
                rows,
                notes="target <= 0.10 and <= 0.5 mm RMS at every peak (issue #31)",
            ),
        ],
        **describe(__doc__, "bench_dense"),
        headline={"dense_s_per_frame": dense_s, "track_s_per_frame": track_s},
    )


if __name__ == "__main__":
    main()
