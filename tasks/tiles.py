"""Stage ``tiles``: the model-fit and kinematic-scan tiles of the panel video.

They depend on the alignment only, so they render while the tissue is meshed, and no
material edit renders them again; ``render`` adds the capture and the FEM tiles. The tile
size, frame stride and turntable are the ``render`` section's (one setting for every tile).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physanim.pipeline import StageContext, StageOutput, StageSpec
from physanim.render.face_panel import FIT_TITLE, KINEMATIC_TITLE, TileParams
from tasks.align import AlignOutput
from tasks.dense import DenseOutput


@dataclass(frozen=True)
class TilesOutput(StageOutput):
    """R rendered frames: ``frames`` (R,) their indices, ``fit`` and ``kinematic`` (R, H, W,
    3) uint8 RGB tiles of the fitted motion mesh and of the captured scan (stage ``dense``)."""

    frames: np.ndarray
    fit: np.ndarray
    kinematic: np.ndarray

    def by_title(self) -> dict[str, np.ndarray]:
        """Panel title -> tiles, in panel order."""
        return {FIT_TITLE: self.fit, KINEMATIC_TITLE: self.kinematic}


def compute(
    params: TileParams, align: AlignOutput, dense: DenseOutput, ctx: StageContext[TileParams]
) -> TilesOutput:
    """The fit and captured-scan tiles at every ``params.every_frames``-th frame."""
    from physanim.render.face_panel import motion_tiles

    tiles = motion_tiles(
        align.motion, align.triangles, dense.motion, align.scan_vertices, align.scan_faces,
        params, ctx.progress,
    )  # fmt: skip
    frames = params.frames(align.motion.shape[0])
    return TilesOutput(frames, tiles[FIT_TITLE], tiles[KINEMATIC_TITLE])


SPEC = StageSpec.typed(
    "tiles",
    compute,
    version="2",
    doc="panel tiles of the model fit and the kinematic scan (render's tile settings)",
    section="render",
)
