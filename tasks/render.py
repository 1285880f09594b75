"""Stage ``render``: side-by-side video of capture | model fit | captured scan | FEM | the
scan and the FEM from the side, plots.

Per frame: the captured colour frame with the tracked landmarks, the CANDIDE-style fit, the
captured scan and the FEM skin coloured by displacement from the front, then the captured
scan and the FEM skin from the side (``side_view_deg``), in one panel
(``physanim.render.face_panel``); PNG frames, an MP4 at the capture frame rate and matplotlib
plots (``physanim.render.plots.plot_face_run``), all in this output's files/. The cropped
capture, the fit and the captured-scan tiles come from the ``tiles`` stage. Version history:
CHANGELOG.md.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from physanim.pipeline import StageContext, StageOutput, StageSpec
from physanim.render.face_panel import PanelParams
from tasks.align import AlignOutput
from tasks.evaluate import EvaluateOutput
from tasks.simulate import SimulateOutput
from tasks.tetra import TetraOutput
from tasks.tiles import TilesOutput
from tasks.track import TrackOutput

#: What the render stage's files show (a report lists those present), path -> caption.
FILES = {
    "panel.mp4": "Capture | fit | captured scan | FEM | captured scan and FEM from the side",
    "fidelity.png": "Motion fidelity against the truth, per region (0 = moves like the actor)",
    "lip_gap.png": "Lip gap: truth, FEM, kinematic scan",
    "jaw.png": "Jaw opening estimated from the tracked mandible landmarks",
    "symmetry.png": "Symmetry cost (tracked, kinematic, FEM)",
    "mouth_corners.png": "Mouth-corner displacement",
    "energies.png": "FEM energies",
}


@dataclass(frozen=True)
class RenderOutput(StageOutput):
    """The render's summary figures (its frames, video and plots are files, see ``FILES``):
    ``frames`` rendered, ``video`` file name, ``codec``."""

    frames: int
    video: str
    codec: str


def compute(
    params: PanelParams,
    track: TrackOutput,
    align: AlignOutput,
    tetra: TetraOutput,
    simulate: SimulateOutput,
    evaluate: EvaluateOutput,
    tiles: TilesOutput,
    ctx: StageContext[PanelParams],
) -> RenderOutput:
    """panel frames + video + plots of the upstream chain."""
    from physanim.render.face_panel import FaceFootage, render_face_panel
    from physanim.render.plots import plot_face_run

    footage = FaceFootage(
        capture=tiles.capture, fps=float(track.fps),
        motion_tiles=tiles.by_title(), scan_vertices=align.scan_vertices,
        scan_faces=align.scan_faces, scan_side=align.scan_side, nodes=tetra.nodes,
        tets=tetra.tets, mouth=align.mouth(),
        displacements=simulate.displacements,
    )  # fmt: skip
    embeddings = ctx.dataset.run_dir / "cache" / "embeddings"
    energies = dict(
        kinetic=simulate.kinetic, strain=simulate.strain, dissipated=simulate.dissipated
    )
    peaks = (evaluate.peak_frames or {}).values()
    with ThreadPoolExecutor(1) as pool:  # the plots draw while the panel's tiles render
        plots = pool.submit(
            plot_face_run, simulate.times, energies, simulate.jaw, evaluate, ctx.files_dir
        )
        done = render_face_panel(footage, params, ctx.files_dir, embeddings, ctx.progress, peaks)
        plots.result()
    n = len(done.frames)
    summary = dict(
        frames=n,
        video=done.video.name,
        codec=done.codec,
        render_s_per_frame=round(done.render_s / max(n, 1), 4),
    )
    return RenderOutput(frames=n, video=done.video.name, codec=done.codec, summary=summary)


SPEC = StageSpec.typed(
    "render",
    compute,
    version="9",
    doc="panel video (capture | fit | captured scan | FEM | scan and FEM from the side), "
    "symmetry / mouth / energy plots",
    files=FILES,
)
