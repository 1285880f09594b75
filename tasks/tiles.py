"""Stage ``tiles``: the capture, model-fit and captured-scan tiles of the panel video.

They depend on the capture, the alignment and the dense capture only, so they render while the
tissue is meshed, and no material edit makes them again; ``render`` adds the FEM tiles. The
capture tiles are the colour frames cropped to the face with the tracked landmarks drawn. The
captured scan is seen from the front and from the side (``side_view_deg``), coloured by its
error against the dataset's ground truth where asked (``scan_colour``). The tile size, frame
stride, turntable and these are the ``render`` section's (one setting for every tile).
"""

from __future__ import annotations

from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from physanim.pipeline import DatasetParams, StageContext, StageOutput, StageSpec
from physanim.render.face_panel import FIT_TITLE, KINEMATIC_TITLE, SIDE, TileParams
from tasks.align import AlignOutput
from tasks.dense import DenseOutput
from tasks.ingest import IngestOutput
from tasks.track import TrackOutput


@dataclass(frozen=True)
class TilesOutput(StageOutput):
    """R rendered frames: ``frames`` (R,) their indices, ``fit`` and ``kinematic`` (R, H, W,
    3) uint8 RGB tiles of the fitted motion mesh and of the captured scan (stage ``dense``)
    from the front, ``kinematic_side`` of the captured scan from the side (None: no side
    view), ``capture`` (R, h, w, 3) uint8 RGB the colour frames cropped to the face with the
    tracked landmarks drawn."""

    frames: np.ndarray
    fit: np.ndarray
    kinematic: np.ndarray
    capture: np.ndarray
    kinematic_side: np.ndarray | None = None

    def by_title(self) -> dict[str, np.ndarray]:
        """Panel title -> tiles, in panel order."""
        side = {} if self.kinematic_side is None else {KINEMATIC_TITLE + SIDE: self.kinematic_side}
        return {FIT_TITLE: self.fit, KINEMATIC_TITLE: self.kinematic, **side}


def fingerprint(dataset: DatasetParams, params: TileParams) -> Mapping[str, object]:
    """The ground truth's files when the scan may be coloured by its error (an edited or
    added truth renders the tiles again); nothing for plain skin."""
    from physanim.evaluate.truth import truth_fingerprint

    return {} if params.scan_colour == "skin" else truth_fingerprint(dataset.path, params.truth)


def compute(
    params: TileParams,
    ingest: IngestOutput,
    track: TrackOutput,
    align: AlignOutput,
    dense: DenseOutput,
    ctx: StageContext[TileParams],
) -> TilesOutput:
    """The capture, fit and captured-scan tiles at every ``params.every_frames``-th frame; the
    scan coloured by its error (mm) where ``params.scan_colour`` asks and the truth is there."""
    from physanim.evaluate.truth import load_truth
    from physanim.render.face_panel import (
        capture_tiles,
        motion_tiles,
        scan_error_mm,
        select_frames,
    )

    truth_path = ctx.dataset_dir / params.truth
    if params.scan_colour == "error" and not truth_path.exists():
        raise ValueError(f"render.scan_colour is 'error', but there is no truth {truth_path}")
    n_frames = align.motion.shape[0]
    frames = params.frames(n_frames)
    captured = select_frames(dense.motion, frames)
    error, summary = None, {"scan_colour": "skin"}
    if params.scan_colour != "skin" and truth_path.exists():
        truth = load_truth(truth_path, n_frames)
        at_frames = replace(truth, vertices=truth.vertices[frames])
        error = scan_error_mm(align.scan_vertices, captured, at_frames)
        summary = {
            "scan_colour": "error",
            "scan_error_mm": {
                "median": round(float(np.nanmedian(error)), 3),
                "p95": round(float(np.nanpercentile(error, 95)), 3),
                "max": round(float(np.nanmax(error)), 3),
            },
            "vertices_without_truth": int(np.isnan(error[0]).sum()),
        }
    with ThreadPoolExecutor(1) as pool:  # the capture is cropped while the tiles render
        crops = pool.submit(
            capture_tiles, ingest.color, track.uv, track.confidence, frames, params.size
        )
        tiles = motion_tiles(
            align.motion[frames], align.triangles, captured, align.scan_vertices,
            align.scan_faces, params, ctx.progress, error,
        )  # fmt: skip
        capture = crops.result()
    side = tiles.get(KINEMATIC_TITLE + SIDE)
    return TilesOutput(
        frames, tiles[FIT_TITLE], tiles[KINEMATIC_TITLE], capture, side, summary=summary
    )


SPEC = StageSpec.typed(
    "tiles",
    compute,
    version="7",
    doc="panel tiles of the capture (cropped, landmarks drawn), the model fit and the captured "
    "scan, front and side, the scan optionally coloured by its error against the truth "
    "(render's tile settings)",
    fingerprint=fingerprint,
    section="render",
)
