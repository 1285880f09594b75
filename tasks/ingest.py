"""Stage ``ingest``: the dataset's recording (bag, RGBD folder or stereo pair) into the store.

Like every module in tasks/, it imports the heavy library parts inside the functions that
need them, so that planning (``physanim status``) never pays for open3d, VTK or numba.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from physanim.capture.frames import StereoRight
from physanim.capture.params import IngestParams
from physanim.pipeline import (
    DatasetParams,
    PipelineConfig,
    ProgressFactory,
    StageContext,
    StageOutput,
    StageSpec,
)


@dataclass(frozen=True)
class IngestOutput(StageOutput):
    """An ingested recording of T frames (``physanim.capture.frames.Capture`` as stored).

    ``color`` (T, H, W, 3) uint8 RGB and ``depth`` (T, H, W) float32 m (NaN invalid), read
    lazily (Zarr arrays); ``K`` (3, 3) px intrinsics; ``depth_scale`` m per raw unit (None:
    stereo); ``timestamps`` (T,) s; ``frame_index`` (T,) on the recording's grid; ``fps``
    frames/s; ``valid_fraction`` (T,); ``depth_median`` (T,) m; the frame-grid findings
    (``dropped``, ``duplicated``, ``recovered``, ``implausible_depth``), ``warnings``, the
    source ``kind``/``origin``, the ``source`` reader and a stereo pair's right images
    (``stereo``, None for depth frames).
    """

    color: np.ndarray = field(metadata={"lazy": True})
    depth: np.ndarray = field(metadata={"lazy": True})
    K: np.ndarray
    depth_scale: float | None
    timestamps: np.ndarray
    frame_index: np.ndarray
    fps: float
    source: str
    valid_fraction: np.ndarray
    depth_median: np.ndarray
    dropped: list[int]
    duplicated: list[int]
    recovered: list[int]
    warnings: list[str]
    implausible_depth: list[int]
    kind: str
    origin: str
    stereo: StereoRight | None = None


def fingerprint(dataset: DatasetParams, params: IngestParams) -> Mapping[str, object]:
    """Name, size and modification time of exactly the files ingest will read
    (``source_files``: never the run directory of a dataset-root layout)."""
    from physanim.capture.ingest import find_source, source_files
    from physanim.store import files_fingerprint

    try:
        kind, path = find_source(dataset.path, params.source)
    except (FileNotFoundError, ValueError):
        return {"missing": str(dataset.path)}  # ingest itself reports what is missing
    return {"source": kind, "files": files_fingerprint(source_files(kind, path), dataset.path)}


def compute(params: IngestParams, ctx: StageContext[IngestParams]) -> IngestOutput:
    """colour (T,H,W,3) uint8, depth (T,H,W) float32 m (NaN invalid), K, timestamps (T,) s."""
    from physanim.capture.ingest import load_capture

    capture = load_capture(ctx.dataset_dir, params, ctx.progress("ingest"))
    summary = dict(
        source=capture.source,
        frames=capture.n_frames,
        fps=capture.fps,
        mean_valid_depth_fraction=round(float(capture.valid_fraction.mean()), 4),
        dropped=capture.dropped,
        duplicated=capture.duplicated,
        recovered=capture.recovered,
        implausible_depth_frames=capture.implausible_depth,
        warnings=capture.warnings,
    )
    arrays = {f.name: getattr(capture, f.name) for f in fields(IngestOutput) if f.name != "summary"}
    return IngestOutput(**arrays, summary=summary)


SPEC = StageSpec.typed(
    "ingest",
    compute,
    version="4",
    doc="RealSense bag / Open3D RGBD folder / stereo pair -> colour, metric depth, intrinsics",
    fingerprint=fingerprint,
)


def ensure_demo(
    config: PipelineConfig,
    progress: ProgressFactory | None = None,
    starting: Callable[[], None] | None = None,
) -> Path | None:
    """Generate the demo dataset when the config names ``demo``, or a library dataset when
    it names one (``physanim.capture.library.dataset_name``: ``lips-s1-coarse``, its
    performance, seed, frames and markers from the name, the rest from the ``demo``
    section), and it has no recording yet; ``starting`` is called first (the CLI starts
    Prefect's server then, to come up meanwhile).

    Returns the generated directory, or None when nothing had to be done.
    """
    from physanim.capture.ingest import has_recording
    from physanim.capture.library import library_params
    from physanim.capture.params import DemoParams

    dataset = config.dataset
    if has_recording(dataset.path):
        return None
    demo = library_params(dataset.name, config.section("demo", DemoParams))
    if demo is None:
        return None
    from physanim.capture.demo import generate_demo  # open3d: only when generating

    if starting is not None:
        starting()
    report = progress(f"{dataset.name} dataset") if progress else None
    return generate_demo(dataset.path, params=demo, progress=report)
