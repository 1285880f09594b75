"""Stage ``render``: side-by-side video of capture | model fit | kinematic scan | FEM, plots.

Per frame: the captured colour frame with the tracked landmarks, the CANDIDE-style fit, the
kinematic (bound) scan and the FEM skin coloured by displacement, in one panel; PNG frames,
an MP4 at the capture frame rate and matplotlib plots, all in this output's files/.
"""

from __future__ import annotations

import hashlib
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from physanim.evaluate.face import FaceEvaluation
from physanim.pipeline import StageContext, StageSpec
from tasks.align import AlignOutput
from tasks.ingest import IngestOutput
from tasks.simulate import SimulateOutput
from tasks.tetra import TetraOutput
from tasks.track import TrackOutput

#: What the render stage's files show (a report lists those present), path -> caption.
FILES = {
    "panel.mp4": "Capture | fit | kinematic scan | FEM",
    "fidelity.png": "Motion fidelity against the truth, per region (0 = moves like the actor)",
    "lip_gap.png": "Lip gap: truth, FEM, kinematic scan",
    "jaw.png": "Jaw opening estimated from the tracked mandible landmarks",
    "symmetry.png": "Symmetry cost (tracked, kinematic, FEM)",
    "mouth_corners.png": "Mouth-corner displacement",
    "energies.png": "FEM energies",
}


class RenderParams(BaseModel):
    """Rendering settings."""

    model_config = ConfigDict(extra="forbid")
    tile_width_px: int = Field(480, ge=64, le=4096, description="width of each panel tile, px")
    tile_height_px: int = Field(640, ge=64, le=4096, description="height of each tile, px")
    every_frames: int = Field(1, ge=1, le=1000, description="render every n-th frame")
    png_frames: bool = Field(True, description="also keep each panel as a PNG")
    displacement_max_mm: float = Field(
        0.0, ge=0.0, le=100.0, description="colour-bar top, mm (0: the run's maximum)"
    )
    turntable: bool = Field(False, description="turn the 3D tiles once around over the video")


@dataclass(frozen=True)
class RenderOutput:
    """The render's summary figures (its frames, video and plots are files, see ``FILES``):
    ``frames`` rendered, ``video`` file name, ``codec``."""

    frames: int
    video: str
    codec: str


class TileCache:
    """Rendered tile sequences of uncoloured meshes by the content of their inputs, in
    ``folder`` (.npy); the ``keep`` most recently used stay."""

    def __init__(self, folder: Path, keep: int = 4) -> None:
        self.folder, self.keep = folder, keep

    def render(self, **job: Any) -> Any:
        """``render_sequence(**job)``, or its earlier result for the same inputs."""
        import numpy as np

        import physanim.render.face as face

        digest = hashlib.sha256(b"".join(f.read_bytes() for f in face.CODE_FILES))  # its code too
        for name in sorted(job):
            if name != "progress":
                value = job[name]
                data = value.tobytes() if isinstance(value, np.ndarray) else repr(value).encode()
                digest.update(name.encode() + b"=" + data)
        path = self.folder / f"{digest.hexdigest()[:32]}.npy"
        if path.exists():
            try:
                tiles = np.load(path)
                path.touch()
                if job.get("progress") is not None:
                    job["progress"](len(tiles), len(tiles))
                return tiles
            except (OSError, ValueError):
                path.unlink(missing_ok=True)
        tiles = face.render_sequence(**job)
        self.folder.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.npy")
        np.save(tmp, tiles)
        tmp.replace(path)
        for old in sorted(self.folder.glob("*.npy"), key=lambda p: p.stat().st_mtime)[: -self.keep]:
            old.unlink(missing_ok=True)
        return tiles


def compute(
    params: RenderParams,
    ingest: IngestOutput,
    track: TrackOutput,
    align: AlignOutput,
    tetra: TetraOutput,
    simulate: SimulateOutput,
    evaluate: FaceEvaluation,
    ctx: StageContext[RenderParams],
) -> RenderOutput:
    """panel frames + video + plots of the upstream chain."""
    import numpy as np

    from physanim.mesh.embed import embedding_matrix
    from physanim.mesh.kinematic import blend_frames
    from physanim.render.camera import frontal_camera
    from physanim.render.colours import ColourMap
    from physanim.render.crop import face_crop
    from physanim.render.face import render_sequence
    from physanim.render.panel import draw_landmarks, panel, write_mp4
    from physanim.render.plots import (
        plot_energies,
        plot_fidelity,
        plot_jaw,
        plot_lip_gap,
        plot_mouth_corners,
        plot_symmetry_cost,
    )

    sim, ev = simulate, evaluate
    frames = np.arange(0, sim.displacements.shape[0], params.every_frames)
    size = (params.tile_width_px, params.tile_height_px)

    scan_v, scan_f = align.scan_vertices, align.scan_faces
    camera = frontal_camera(scan_v, size, bar=True)
    # the FEM tile shows the high-res scan embedded in the tets, moved by their displacement
    nodes, tets = tetra.nodes, tetra.tets
    mouth = align.mouth()
    embed = embedding_matrix(
        scan_v, align.scan_side, nodes, tets, mouth.side(nodes[tets].mean(axis=1))
    )
    disp = blend_frames(embed, sim.displacements[frames])
    magnitude_mm = np.linalg.norm(disp, axis=-1) * 1e3
    top = params.displacement_max_mm or max(float(magnitude_mm.max()), 1e-3)
    bar = ColourMap("displacement (mm)", clim=(0.0, top))

    azimuth = np.linspace(0.0, 360.0, len(frames), endpoint=False) if params.turntable else None
    t0 = time.perf_counter()
    jobs = {
        "CANDIDE-style fit": dict(
            vertices=align.motion[frames], faces=align.triangles,
            progress=ctx.progress("render fit"),
        ),
        "kinematic scan": dict(
            vertices=align.kinematic.get_orthogonal_selection(
                (frames, slice(None), slice(None))
            ),
            faces=scan_f, progress=ctx.progress("render kinematic"),
        ),
        "FEM": dict(
            vertices=scan_v[None] + disp, faces=scan_f, scalars=magnitude_mm, colour_map=bar,
            progress=ctx.progress("render FEM"),
        ),
    }  # fmt: skip
    # the three sequences render at once, each in its own worker process; the fit and
    # kinematic tiles, which no material edit changes, come from the run's tile cache
    cache = TileCache(ctx.dataset.run_dir / "cache" / "render-tiles")
    with ThreadPoolExecutor(len(jobs)) as pool:
        futures = {
            name: pool.submit(
                render_sequence if name == "FEM" else cache.render,
                **job, camera=camera, size=size, azimuth_deg=azimuth,
            )
            for name, job in jobs.items()
        }  # fmt: skip
        tiles = {name: f.result() for name, f in futures.items()}
    render_s = time.perf_counter() - t0
    colour = ingest.color.get_orthogonal_selection((frames,))
    uv, conf = track.uv[frames], track.confidence[frames]

    out = ctx.files_dir
    (out / "frames").mkdir(exist_ok=True)
    panels = []
    # the capture cropped to the face: the landmarks' box + 60 %, with the aspect of a tile
    box = face_crop(uv, colour.shape[1:3], size)
    offset = np.array([box[2], box[0]])
    for i, t in enumerate(frames):
        crop = np.ascontiguousarray(colour[i, box[0] : box[1], box[2] : box[3]])
        captured = draw_landmarks(crop, uv[i] - offset, conf[i], radius=2)
        images = [captured, *(v[i] for v in tiles.values())]
        frame = panel(images, [f"capture t={t / float(track.fps):.2f} s", *tiles])
        panels.append(frame)
    fps = float(track.fps) / params.every_frames

    def write_pngs() -> None:
        import cv2

        for t, frame in zip(frames, panels, strict=True):  # fast zlib level: 3x quicker
            path = str(out / "frames" / f"{t:04d}.png")
            cv2.imwrite(path, frame[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 1])

    with ThreadPoolExecutor(1) as pool:  # PNGs while FFmpeg encodes the video
        pngs = pool.submit(write_pngs) if params.png_frames else None
        video, codec = write_mp4(panels, out / "panel.mp4", fps)
        if pngs is not None:
            pngs.result()

    time_s = np.asarray(sim.times)
    ch = ev.mouth_corners
    variants = {"tracked": ev.tracked, "kinematic": ev.kinematic, "fem": ev.fem}
    plot_symmetry_cost(time_s, {v: m.cost for v, m in variants.items()}, out / "symmetry")
    corners = {v: m.displacement[:, ch] for v, m in variants.items()}
    plot_mouth_corners(time_s, corners, out / "mouth_corners")
    energies = {"kinetic": sim.kinetic, "strain": sim.strain, "dissipated": sim.dissipated}
    plot_energies(time_s, {"fem": energies}, out / "energies")
    if sim.jaw is not None:
        plot_jaw(time_s, sim.jaw.angle, sim.jaw.residual_m, out / "jaw")
    if ev.lip_gap_truth is not None and ev.fidelity_fem and ev.fidelity_kinematic:
        fidelity = {"fem": ev.fidelity_fem, "kinematic": ev.fidelity_kinematic}
        peaks = {k: float(time_s[v]) for k, v in (ev.peak_frames or {}).items()}
        plot_fidelity(
            time_s, {m: f.overall for m, f in fidelity.items()},
            {m: f.regions for m, f in fidelity.items()}, list(ev.regions or []),
            out / "fidelity", peaks=peaks,
        )  # fmt: skip
        gaps = {"truth": ev.lip_gap_truth, "fem": ev.lip_gap_fem, "kinematic": ev.lip_gap_kinematic}
        plot_lip_gap(time_s, gaps, out / "lip_gap")
    ctx.summary.update(
        frames=len(frames),
        video=video.name,
        codec=codec,
        render_s_per_frame=round(render_s / max(len(frames), 1), 4),
    )
    return RenderOutput(frames=len(frames), video=video.name, codec=codec)


SPEC = StageSpec.typed(
    "render",
    compute,
    version="4",
    doc="panel video (capture | fit | kinematic | FEM), symmetry / mouth / energy plots",
    files=FILES,
)
