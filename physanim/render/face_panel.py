"""The face run's panel video: capture | model fit | captured scan | FEM | side views.

Per rendered frame: the captured colour frame cropped to the face with the tracked landmarks,
the CANDIDE-style fit, the captured scan (plain skin, or coloured by its error against the
dataset's ground truth) and the FEM skin (the high-res scan embedded in the tets) coloured by
displacement, all seen from the front; then the captured scan and the FEM skin seen from the
side (``side_view_deg``), where motion towards the camera (a pucker, a cheek puff) shows. The
panels as PNGs and an MP4 at the capture frame rate (divided by the frame stride).
"""

from __future__ import annotations

import os
import time
from collections.abc import Collection, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator

from physanim.mesh.seam import MouthLine
from physanim.pipeline import ProgressFactory, ProgressFn

if TYPE_CHECKING:
    from physanim.evaluate.truth import Truth
    from physanim.render.colours import ColourMap

#: Panel titles of the frontal 3D tiles, in panel order (the capture's comes first).
FIT_TITLE, KINEMATIC_TITLE, FEM_TITLE = "CANDIDE-style fit", "captured scan", "FEM"
#: What a side view's title adds to its frontal tile's title.
SIDE = " (side)"
#: Colour-bar label of the captured scan's error.
ERROR_LABEL = "error vs truth (mm; grey: no truth)"


class TileParams(BaseModel):
    """What the 3D tiles share: their size, the frame stride and the camera's path."""

    model_config = ConfigDict(extra="forbid")
    tile_width_px: int = Field(480, ge=64, le=4096, description="width of each panel tile, px")
    tile_height_px: int = Field(640, ge=64, le=4096, description="height of each tile, px")
    every_frames: int = Field(1, ge=1, le=1000, description="render every n-th frame")
    turntable: bool = Field(False, description="turn the 3D tiles once around over the video")
    side_view_deg: float = Field(
        70.0, ge=0.0, le=90.0,
        description="side tiles of the captured scan and the FEM skin: their camera turned this "
        "far from the front towards the actor's left, deg (90: profile; 0: no side tiles)",
    )  # fmt: skip
    scan_colour: Literal["skin", "error", "auto"] = Field(
        "auto",
        description="captured-scan tiles: 'skin', 'error' (per vertex, the distance of its "
        "displacement to the ground truth's, mm; the dataset must have a truth) or 'auto' "
        "(error where the dataset has a truth, else skin)",
    )
    truth: str = Field(
        "ground_truth.zarr", description="ground truth in the dataset (as evaluate's), if any"
    )
    error_max_mm: float = Field(
        0.0, ge=0.0, le=100.0,
        description="error colour-bar top, mm (0: the 99th percentile over the vertices of "
        "each one's largest error in the rendered frames; larger ones show in the top colour)",
    )  # fmt: skip

    def frames(self, n_frames: int) -> NDArray:
        """(R,) the frame indices rendered of ``n_frames``."""
        return np.arange(0, n_frames, self.every_frames)

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) px of a tile."""
        return (self.tile_width_px, self.tile_height_px)

    def azimuth(self, n_rendered: int) -> NDArray | None:
        """(R,) camera azimuths in degrees of a turntable over ``n_rendered`` tiles, or None."""
        if not self.turntable:
            return None
        return np.linspace(0.0, 360.0, n_rendered, endpoint=False)

    @property
    def views_deg(self) -> tuple[float, ...]:
        """Camera azimuths, deg, of the captured scan's and the FEM's tiles: the front, then
        the side view if any."""
        return (0.0, self.side_view_deg) if self.side_view_deg else (0.0,)

    def error_colours(self, error_mm: NDArray) -> ColourMap:
        """The colour map of the captured scan's ``error_mm`` (R, N): from 0 to
        ``error_max_mm`` or the 99th percentile of each vertex's largest error over the R
        frames. Not the percentile of all R x N errors: most are of skin at rest, and the
        demo's chin at the jaw drop (a few frames of a tenth of the scan) was saturated in the
        top colour at 0.7 mm; nor the largest error: a few wild vertices at the scan's edge
        would leave the rest of the face in the bottom colour. NaN (no truth) is left out
        and drawn grey."""
        from physanim.render.colours import ColourMap

        worst = np.asarray(error_mm).max(axis=0)
        worst = worst[np.isfinite(worst)]
        top = self.error_max_mm or max(float(np.percentile(worst, 99)) if len(worst) else 0, 1e-3)
        return ColourMap(ERROR_LABEL, clim=(0.0, top), cmap="BuPu")


class PanelParams(TileParams):
    """Rendering settings."""

    png_frames: Literal["peaks", "all", "none"] = Field(
        "peaks",
        description="panels also kept as PNG (frames/<frame>.png): 'peaks' = the evaluated "
        "expressions' peak frames (the report shows them; about 70 ms per PNG), 'all', or "
        "'none' (true / false read as 'all' / 'none')",
    )
    displacement_max_mm: float = Field(
        0.0, ge=0.0, le=100.0, description="colour-bar top, mm (0: the run's maximum)"
    )

    @field_validator("png_frames", mode="before")
    @classmethod
    def _from_bool(cls, value: Any) -> Any:
        return {True: "all", False: "none"}.get(value, value) if isinstance(value, bool) else value


@dataclass(frozen=True)
class FaceFootage:
    """One face run as the panel shows it (T frames; R rendered frames).

    ``capture`` (R, h, w, 3) uint8 RGB capture tiles of the rendered frames, cropped to the
    face with the landmarks drawn (:func:`capture_tiles`); ``fps`` frames/s of the capture;
    ``motion_tiles`` title -> (R, H, W, 3) uint8 tiles of the rendered frames already
    rendered (:func:`motion_tiles`, side views included); ``scan_vertices`` (N, 3) m,
    ``scan_faces`` (F, 3), ``scan_side`` (N,) lip sides; ``nodes`` (n, 3) m, ``tets`` (M,
    4), ``mouth`` the lip seam; ``displacements`` (T, n, 3) m of the FEM nodes.
    """

    capture: NDArray
    fps: float
    motion_tiles: Mapping[str, NDArray]
    scan_vertices: NDArray
    scan_faces: NDArray
    scan_side: NDArray
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
    embeddings: Path,
    progress: ProgressFactory,
    peaks: Collection[int] = (),
) -> FacePanel:
    """Render every ``params.every_frames``-th frame of ``footage`` as a panel into
    ``folder``: ``panel.mp4`` and, as ``params.png_frames`` asks, ``frames/<frame>.png``
    (``peaks``: the frames 'peaks' keeps). The FEM tiles render in worker processes
    (``embeddings``: the folder caching the scan's embedding in the tets); the capture, fit and
    captured-scan tiles come made (``footage``). Panel order: the capture, the frontal tiles,
    then the side views."""
    frames = params.frames(footage.displacements.shape[0])
    t0 = time.perf_counter()
    fem = fem_tiles(footage, frames, params, embeddings, progress("render FEM"))
    tiles = {**footage.motion_tiles, **_titled(FEM_TITLE, fem)}
    render_s = time.perf_counter() - t0
    rendered = {t: tiles[t] for t in sorted(tiles, key=lambda t: t.endswith(SIDE))}
    panels = compose_panels(footage, frames, footage.capture, rendered)
    keep = {"all": frames, "none": (), "peaks": peaks}[params.png_frames]
    fps = footage.fps / params.every_frames
    video, codec = write_panels(panels, frames, folder, fps, set(keep))
    return FacePanel(frames, video, codec, render_s)


def motion_tiles(
    fit_motion: NDArray,
    fit_triangles: NDArray,
    captured: NDArray,
    scan_vertices: NDArray,
    scan_faces: NDArray,
    params: TileParams,
    progress: ProgressFactory,
    error_mm: NDArray | None = None,
) -> dict[str, NDArray]:
    """Title -> (R, H, W, 3) uint8 tiles of R rendered frames of the fitted motion mesh
    (``fit_motion`` (R, V, 3) m, ``fit_triangles``) and of the captured scan (``captured``
    (R, N, 3) m on ``scan_faces``; from the front and the side, ``params.views_deg``), the
    two meshes rendered side by side, by the cameras of the FEM tiles (framed on
    ``scan_vertices`` (N, 3) m). ``error_mm`` (R, N): the scan's error, mm, coloured with a
    colour bar (None: plain skin)."""
    from physanim.render.face import render_views

    scan_colours = {} if error_mm is None else dict(
        scalars=error_mm, colour_map=params.error_colours(error_mm)
    )  # fmt: skip
    jobs = {
        FIT_TITLE: dict(
            vertices=fit_motion, faces=fit_triangles, views_deg=(0.0,),
            progress=progress("render fit"),
        ),
        KINEMATIC_TITLE: dict(
            vertices=captured, faces=scan_faces, views_deg=params.views_deg,
            progress=progress("render captured scan"), **scan_colours,
        ),
    }  # fmt: skip
    look = dict(
        camera=_camera(scan_vertices, params), size=params.size,
        azimuth_deg=params.azimuth(len(captured)),
    )  # fmt: skip
    threads = _share_of_cores(len(jobs))
    with ThreadPoolExecutor(len(jobs)) as pool:
        futures = {
            name: pool.submit(render_views, **job, **look, threads=threads)
            for name, job in jobs.items()
        }
        return {k: v for name, f in futures.items() for k, v in _titled(name, f.result()).items()}


def scan_error_mm(scan_vertices: NDArray, captured: NDArray, truth: Truth) -> NDArray:
    """(R, N) mm per scan vertex and frame: the distance between its captured displacement
    (``captured`` (R, N, 3) m minus ``scan_vertices`` (N, 3) m) and its true one (the truth's
    surface point closest to it at the first frame, followed; ``truth`` the same R frames,
    the first the neutral one); NaN where the vertex has no truth (farther than
    ``evaluate``'s default ``truth_max_distance_m`` from the true surface: a filled hole of
    the scan)."""
    from physanim.evaluate.fidelity import follow_truth

    true = follow_truth(scan_vertices, truth.vertices, truth.faces)
    error = 1e3 * np.linalg.norm(captured - scan_vertices - true.displacement, axis=-1)
    return np.where(true.on_truth(), error, np.nan)


def fem_tiles(
    footage: FaceFootage,
    frames: NDArray,
    params: PanelParams,
    embeddings: Path,
    progress: ProgressFn,
) -> NDArray:
    """(V, R, H, W, 3) uint8 tiles of the FEM skin at ``frames`` (R,) from each of
    ``params.views_deg`` (V,): the high-res scan embedded in the tets, moved by their
    displacement and coloured by it (mm, with a colour bar); the embedding is kept in the
    folder ``embeddings`` by the content of its inputs."""
    from physanim.mesh.embed import embedded_displacements
    from physanim.render.colours import ColourMap
    from physanim.render.face import render_views
    from physanim.store.file_cache import FileCache

    scan_v = footage.scan_vertices
    disp = embedded_displacements(
        scan_v, footage.scan_side, footage.nodes, footage.tets, footage.mouth,
        footage.displacements[frames], FileCache(embeddings, keep=4),
    )  # fmt: skip
    magnitude_mm = np.linalg.norm(disp, axis=-1) * 1e3
    top = params.displacement_max_mm or max(float(magnitude_mm.max()), 1e-3)
    return render_views(
        scan_v[None] + disp, footage.scan_faces, params.views_deg, scalars=magnitude_mm,
        colour_map=ColourMap("displacement (mm)", clim=(0.0, top)), progress=progress,
        camera=_camera(scan_v, params), size=params.size, azimuth_deg=params.azimuth(len(frames)),
    )  # fmt: skip


def _share_of_cores(workers: int) -> int:
    """Rasteriser threads of each of ``workers`` renders running at once."""
    return max(1, len(os.sched_getaffinity(0)) // workers)


def _titled(title: str, views: NDArray) -> dict[str, NDArray]:
    """Panel title -> tiles of ``views`` (V, R, H, W, 3): the front's ``title``, the side's
    marked ``SIDE``."""
    return {title: views[0], **({title + SIDE: views[1]} if len(views) > 1 else {})}


def _camera(scan_vertices: NDArray, params: TileParams) -> Any:
    """The frontal camera of every 3D tile, framed on the scan (room for the colour bar); the
    side views turn it about its view-up axis."""
    from physanim.cameras import frontal_camera
    from physanim.render.colours import BAR_HEIGHT

    return frontal_camera(scan_vertices, params.size, bar_px=BAR_HEIGHT)


def capture_tiles(
    colour: Any, uv: NDArray, confidence: NDArray, frames: NDArray, size: tuple[int, int]
) -> NDArray:
    """(R, h, w, 3) uint8: the capture ``colour`` (T, H, W, 3) uint8 RGB (numpy or Zarr) at
    ``frames`` (R,) cropped to the face (the box of the tracked landmarks ``uv`` (T, K, 2) px
    + 60 %, with the aspect of a tile of ``size`` (W, H) px; one box for every frame) with the
    landmarks drawn (``confidence`` (T, K) in [0, 1])."""
    from physanim.render.crop import face_crop
    from physanim.render.panel import draw_landmarks

    images = select_frames(colour, frames)
    uv, conf = uv[frames], confidence[frames]
    box = face_crop(uv, images.shape[1:3], size)
    offset = np.array([box[2], box[0]])
    return np.stack(
        [
            draw_landmarks(
                np.ascontiguousarray(images[i, box[0] : box[1], box[2] : box[3]]),
                uv[i] - offset,
                conf[i],
                radius=2,
            )
            for i in range(len(frames))
        ]
    )


def compose_panels(
    footage: FaceFootage, frames: NDArray, captured: NDArray, tiles: dict[str, NDArray]
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


def select_frames(array: Any, frames: NDArray) -> NDArray:
    """``array[frames]`` of a numpy or Zarr array, frames first."""
    if isinstance(array, np.ndarray):
        return array[frames]
    return np.asarray(array.get_orthogonal_selection((frames,)))
