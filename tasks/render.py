"""Stage ``render``: side-by-side video of capture | model fit | captured scan | FEM | the
scan and the FEM from the side, the simulation's plots.

Per frame: the captured colour frame with the tracked landmarks, the CANDIDE-style fit, the
captured scan and the FEM skin coloured by displacement from the front, then the captured
scan and the FEM skin from the side (``side_view_deg``), in one panel
(``physanim.render.face_panel``); PNG frames, an MP4 at the capture frame rate and the FEM's
energy and jaw plots (``physanim.render.plots.plot_simulation``), all in this output's files/.
The cropped capture, the fit and the captured-scan tiles come from the ``tiles`` stage; the
peak frames kept as PNGs from the ground truth. It does not wait for ``evaluate`` (which draws
the evaluation's plots): the two run side by side. Version history: CHANGELOG.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from physanim.pipeline import DatasetParams, StageContext, StageOutput, StageSpec
from physanim.render.face_panel import PanelParams
from tasks.align import AlignOutput
from tasks.simulate import SimulateOutput
from tasks.tetra import TetraOutput
from tasks.tiles import TilesOutput
from tasks.track import TrackOutput

#: What the render stage's files show (a report lists those present), path -> caption.
FILES = {
    "panel.mp4": "Capture | fit | captured scan | FEM | captured scan and FEM from the side",
    "jaw.png": "Jaw opening estimated from the tracked mandible landmarks",
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
    tiles: TilesOutput,
    ctx: StageContext[PanelParams],
) -> RenderOutput:
    """panel frames + video + plots of the upstream chain."""
    from physanim.evaluate.truth import truth_peaks
    from physanim.render.face_panel import FaceFootage, render_face_panel
    from physanim.render.plots import plot_simulation

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
    peaks = (
        truth_peaks(ctx.dataset_dir / params.truth, len(simulate.times)).values()
        if params.png_frames == "peaks"
        else ()
    )  # the truth is read (and in the key) only where its peaks are kept
    with ThreadPoolExecutor(1) as pool:  # the plots draw while the panel's tiles render
        plots = pool.submit(plot_simulation, simulate.times, energies, simulate.jaw, ctx.files_dir)
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


def fingerprint(dataset: DatasetParams, params: PanelParams) -> Mapping[str, object]:
    """The ground truth's files when its peak frames are kept as PNGs (an edited or added
    truth renders again); nothing otherwise."""
    from physanim.evaluate.truth import truth_fingerprint

    return truth_fingerprint(dataset.path, params.truth) if params.png_frames == "peaks" else {}


SPEC = StageSpec.typed(
    "render",
    compute,
    version="12",
    doc="panel video (capture | fit | captured scan | FEM | scan and FEM from the side), "
    "energy and jaw plots",
    files=FILES,
    fingerprint=fingerprint,
)
