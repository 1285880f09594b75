"""The face run's panel video: capture | model fit | kinematic scan | FEM, side by side.

Per rendered frame: the captured colour frame cropped to the face with the tracked landmarks,
the CANDIDE-style fit, the kinematic (bound) scan and the FEM skin (the high-res scan
embedded in the tets) coloured by displacement; the panels as PNGs and an MP4 at the
capture frame rate (divided by the frame stride).
"""

from __future__ import annotations

import time
from collections.abc import Collection
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator

from physanim.mesh.seam import MouthLine
from physanim.pipeline import ProgressFactory


class PanelParams(BaseModel):
    """Rendering settings."""

    model_config = ConfigDict(extra="forbid")
    tile_width_px: int = Field(480, ge=64, le=4096, description="width of each panel tile, px")
    tile_height_px: int = Field(640, ge=64, le=4096, description="height of each tile, px")
    every_frames: int = Field(1, ge=1, le=1000, description="render every n-th frame")
    png_frames: Literal["peaks", "all", "none"] = Field(
        "peaks",
        description="panels also kept as PNG (frames/<frame>.png): 'peaks' = the evaluated "
        "expressions' peak frames (the report shows them; about 70 ms per PNG), 'all', or "
        "'none' (true / false read as 'all' / 'none')",
    )
    displacement_max_mm: float = Field(
        0.0, ge=0.0, le=100.0, description="colour-bar top, mm (0: the run's maximum)"
    )
    turntable: bool = Field(False, description="turn the 3D tiles once around over the video")

    @field_validator("png_frames", mode="before")
    @classmethod
    def _from_bool(cls, value: Any) -> Any:
        return {True: "all", False: "none"}.get(value, value) if isinstance(value, bool) else value


@dataclass(frozen=True)
class FaceFootage:
    """One face run as the panel shows it (T frames; the arrays marked lazy may be Zarr).

    ``colour`` (T, H, W, 3) uint8 RGB capture (lazy); ``uv`` (T, K, 2) px tracked landmarks
    (NaN: unseen), ``confidence`` (T, K) in [0, 1]; ``fps`` frames/s of the capture;
    ``fit_motion`` (T, V, 3) m the fitted motion mesh in the scan frame, ``fit_triangles``
    (F_m, 3); ``scan_vertices`` (N, 3) m, ``scan_faces`` (F, 3), ``scan_side`` (N,) lip
    sides; ``kinematic`` (T, N, 3) m the kinematic scan (lazy); ``nodes`` (n, 3) m, ``tets``
    (M, 4), ``mouth`` the lip seam; ``displacements`` (T, n, 3) m of the FEM nodes.
    """

    colour: Any
    uv: NDArray
    confidence: NDArray
    fps: float
    fit_motion: NDArray
    fit_triangles: NDArray
    scan_vertices: NDArray
    scan_faces: NDArray
    scan_side: NDArray
    kinematic: Any
    nodes: NDArray
    tets: NDArray
    mouth: MouthLine
    displacements: NDArray


@dataclass(frozen=True)
class FacePanel:
    """What ``render_face_panel`` wrote: ``frames`` (R,) the rendered frame indices, the
    ``video`` path and its ``codec``, ``render_s`` s spent rendering the 3D tiles."""

    frames: NDArray
    video: Path
    codec: str
    render_s: float


def render_face_panel(
    footage: FaceFootage,
    params: PanelParams,
    folder: Path,
    cache_dir: Path,
    progress: ProgressFactory,
    peaks: Collection[int] = (),
) -> FacePanel:
    """Render every ``params.every_frames``-th frame of ``footage`` as a panel into
    ``folder``: ``panel.mp4`` and, as ``params.png_frames`` asks, ``frames/<frame>.png``
    (``peaks``: the frames 'peaks' keeps).

    The 3D tiles render in worker processes while this one crops the capture; the fit and
    kinematic tiles, which no material edit changes, come from the tile cache in
    ``cache_dir`` when their inputs did not change."""
    frames = np.arange(0, footage.displacements.shape[0], params.every_frames)
    size = (params.tile_width_px, params.tile_height_px)
    t0 = time.perf_counter()
    with ThreadPoolExecutor(1) as pool:
        tiles = pool.submit(model_tiles, footage, frames, params, cache_dir, progress)
        captured = capture_tiles(footage, frames, size)
        rendered = tiles.result()
    render_s = time.perf_counter() - t0
    panels = compose_panels(footage, frames, captured, rendered)
    keep = {"all": frames, "none": (), "peaks": peaks}[params.png_frames]
    fps = footage.fps / params.every_frames
    video, codec = write_panels(panels, frames, folder, fps, set(keep))
    return FacePanel(frames, video, codec, render_s)


def model_tiles(
    footage: FaceFootage,
    frames: NDArray,
    params: PanelParams,
    cache_dir: Path,
    progress: ProgressFactory,
) -> dict[str, NDArray]:
    """Title -> (R, H, W, 3) uint8 tiles of the fit, the kinematic scan and the FEM skin
    (coloured by displacement, mm) at ``frames`` (R,), seen by one frontal camera.

    The three sequences render at once, each in its own worker process; the fit and
    kinematic ones through a :class:`~physanim.render.tile_cache.TileCache` in ``cache_dir``."""
    from physanim.mesh.embed import embedded_displacements
    from physanim.render.camera import frontal_camera
    from physanim.render.colours import ColourMap
    from physanim.render.face import render_sequence
    from physanim.render.tile_cache import TileCache
    from physanim.store.file_cache import FileCache

    size = (params.tile_width_px, params.tile_height_px)
    scan_v, scan_f = footage.scan_vertices, footage.scan_faces
    camera = frontal_camera(scan_v, size, bar=True)
    # the FEM tile shows the high-res scan embedded in the tets, moved by their displacement
    disp = embedded_displacements(
        scan_v, footage.scan_side, footage.nodes, footage.tets, footage.mouth,
        footage.displacements[frames], FileCache(cache_dir.with_name("embeddings"), keep=4),
    )  # fmt: skip
    magnitude_mm = np.linalg.norm(disp, axis=-1) * 1e3
    top = params.displacement_max_mm or max(float(magnitude_mm.max()), 1e-3)
    bar = ColourMap("displacement (mm)", clim=(0.0, top))
    azimuth = np.linspace(0.0, 360.0, len(frames), endpoint=False) if params.turntable else None
    jobs = {
        "CANDIDE-style fit": dict(
            vertices=footage.fit_motion[frames], faces=footage.fit_triangles,
            progress=progress("render fit"),
        ),
        "kinematic scan": dict(
            vertices=_frames(footage.kinematic, frames), faces=scan_f,
            progress=progress("render kinematic"),
        ),
        "FEM": dict(
            vertices=scan_v[None] + disp, faces=scan_f, scalars=magnitude_mm, colour_map=bar,
            progress=progress("render FEM"),
        ),
    }  # fmt: skip
    cache = TileCache(cache_dir)
    with ThreadPoolExecutor(len(jobs)) as pool:
        futures = {
            name: pool.submit(
                render_sequence if name == "FEM" else cache.render,
                **job, camera=camera, size=size, azimuth_deg=azimuth,
            )
            for name, job in jobs.items()
        }  # fmt: skip
        return {name: f.result() for name, f in futures.items()}


def capture_tiles(footage: FaceFootage, frames: NDArray, size: tuple[int, int]) -> list[NDArray]:
    """The capture at ``frames`` (R,) cropped to the face (the landmarks' box + 60 %, with the
    aspect of a tile of ``size`` (W, H) px) with the tracked landmarks drawn: R images."""
    from physanim.render.crop import face_crop
    from physanim.render.panel import draw_landmarks

    colour = _frames(footage.colour, frames)
    uv, conf = footage.uv[frames], footage.confidence[frames]
    box = face_crop(uv, colour.shape[1:3], size)
    offset = np.array([box[2], box[0]])
    return [
        draw_landmarks(
            np.ascontiguousarray(colour[i, box[0] : box[1], box[2] : box[3]]),
            uv[i] - offset,
            conf[i],
            radius=2,
        )  # fmt: skip
        for i in range(len(frames))
    ]


def compose_panels(
    footage: FaceFootage, frames: NDArray, captured: list[NDArray], tiles: dict[str, NDArray]
) -> list[NDArray]:
    """Per frame of ``frames`` (R,): its ``captured`` image then the ``tiles`` (title ->
    (R, H, W, 3) uint8) side by side under their titles."""
    from physanim.render.panel import panel

    return [
        panel(
            [captured[i], *(v[i] for v in tiles.values())],
            [f"capture t={t / footage.fps:.2f} s", *tiles],
        )
        for i, t in enumerate(frames)
    ]


def write_panels(
    panels: list[NDArray], frames: NDArray, folder: Path, fps: float, png: Collection[int]
) -> tuple[Path, str]:
    """``folder/panel.mp4`` at ``fps`` frames/s and the panels of the frames in ``png`` as
    ``folder/frames/<frame>.png`` (written while FFmpeg encodes); (video path, codec)."""
    import cv2

    from physanim.render.panel import write_mp4

    (folder / "frames").mkdir(parents=True, exist_ok=True)

    def write_pngs() -> None:
        for t, frame in zip(frames, panels, strict=True):  # fast zlib level: 3x quicker
            if t in png:
                path = str(folder / "frames" / f"{t:04d}.png")
                cv2.imwrite(path, frame[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 1])

    with ThreadPoolExecutor(1) as pool:
        pngs = pool.submit(write_pngs)
        video, codec = write_mp4(panels, folder / "panel.mp4", fps)
        pngs.result()
    return video, codec


def _frames(array: Any, frames: NDArray) -> NDArray:
    """``array[frames]`` of a numpy or Zarr array, frames first."""
    if isinstance(array, np.ndarray):
        return array[frames]
    return np.asarray(array.get_orthogonal_selection((frames,)))
