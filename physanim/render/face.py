"""Offscreen renders of a face surface: lit, smooth-shaded skin or a colour map with a
labelled colour bar, seen by a fixed camera (optionally a turntable).

Two backends give the same images (same camera model, colour mapping, bar and lighting; within
2 grey levels of each other at 99.9 % of the face's pixels, tested; 1 on face000):
- ``"raster"`` (default): the project's compiled z-buffer rasteriser and per-pixel shader
  (:mod:`.raster_backend`), in this process, frames shared out over threads; no OpenGL.
- ``"vtk"``: pyvista/VTK offscreen (EGL or OSMesa, no display needed), lit by VTK's light kit;
  one plotter per sequence, points/normals/colours updated in place. Without a GPU it draws
  through Mesa's llvmpipe, several times slower on these dense scans.

Modules: :mod:`.camera` (camera model, frontal framing, turntable), :mod:`.colours` (skin,
colour maps, colour bar), :mod:`.surface` (one renderer over both backends:
:mod:`.vtk_backend`, :mod:`.raster_backend`), :mod:`.isolated` (VTK in a worker process).
This module renders sequences: ``render_sequence`` from one camera, ``render_views`` from
several (e.g. the front and the side, each frame's normals and colours computed once for all of
them). The VTK backend renders in a separate Python process (``isolate=True``, default: a VTK
crash kills its process). ``render_surface`` and ``SurfaceRenderer`` (:mod:`.surface`) render
in-process (single images and tests).

Frames: actor frame (+x actor's left, +y up, +z out of the face), so the frontal camera sits
on +z and the actor's left appears on the image's right, as in a photograph.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Literal

import numpy as np

from physanim.cameras import Camera, frontal_camera, turntable
from physanim.render.colours import BAR_HEIGHT, SKIN, ColourMap
from physanim.render.isolated import render_isolated
from physanim.render.surface import check_mesh, render_frames

Backend = Literal["raster", "vtk"]


def _frame_scalars(scalars: np.ndarray | None, n_frames: int) -> np.ndarray | None:
    """(T, K) per-frame scalars from (K,) constant or (T, K) scalars."""
    if scalars is None:
        return None
    s = np.asarray(scalars)
    if s.ndim == 1:
        return np.broadcast_to(s, (n_frames, len(s)))
    if s.ndim != 2 or len(s) != n_frames:
        raise ValueError(f"scalars must be (K,) or (T={n_frames}, K); got shape {s.shape}")
    return s


def render_sequence(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    scalars: np.ndarray | None = None,
    colour_map: ColourMap | None = None,
    camera: Camera | None = None,
    azimuth_deg: np.ndarray | Sequence[float] | None = None,
    size: tuple[int, int] = (480, 640),
    colour: tuple[float, float, float] = SKIN,
    backend: Backend = "raster",
    isolate: bool = True,
    progress: Callable[[int, int], None] | None = None,
    threads: int | None = None,
) -> np.ndarray:
    """Render an animated mesh: ``vertices`` (T, N, 3) m, ``faces`` (M, 3) -> (T, H, W, 3)
    uint8, ``size`` = (W, H) px.

    ``scalars``: (N,)/(M,) fixed (e.g. region labels) or (T, N)/(T, M) per frame (e.g.
    displacement in mm, von Mises stress in kPa), drawn with ``colour_map`` (fixed ``clim``
    so colours are comparable over frames).  ``camera`` defaults to the frontal camera of
    frame 0, shared by all frames; ``azimuth_deg`` (T,) turns it per frame (turntable).
    ``backend``: "raster" or "vtk"; ``isolate`` runs VTK in a separate Python process (see
    the module docstring); ``threads`` as in :func:`render_views`.
    """
    return render_views(
        vertices, faces, (0.0,), scalars=scalars, colour_map=colour_map, camera=camera,
        azimuth_deg=azimuth_deg, size=size, colour=colour, backend=backend, isolate=isolate,
        progress=progress, threads=threads,
    )[0]  # fmt: skip


def render_views(
    vertices: np.ndarray,
    faces: np.ndarray,
    views_deg: Sequence[float],
    *,
    scalars: np.ndarray | None = None,
    colour_map: ColourMap | None = None,
    camera: Camera | None = None,
    azimuth_deg: np.ndarray | Sequence[float] | None = None,
    size: tuple[int, int] = (480, 640),
    colour: tuple[float, float, float] = SKIN,
    backend: Backend = "raster",
    isolate: bool = True,
    progress: Callable[[int, int], None] | None = None,
    threads: int | None = None,
) -> np.ndarray:
    """An animated mesh seen from each of ``views_deg`` (V,) camera azimuths, degrees (e.g.
    0 frontal, 70 three-quarter towards the actor's left; added to the turntable's): (V, T,
    H, W, 3) uint8; each frame's normals and colours are computed once for all its views;
    ``progress`` counts the V * T images; ``threads``: the rasteriser's threads, each taking
    a share of the frames (None: one per core; fewer when several renders run at once; with
    VTK, Mesa's). The other arguments as in :func:`render_sequence`."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.ndim != 3 or vertices.shape[2] != 3:
        raise ValueError(f"vertices must be (T, N, 3) metres, got shape {vertices.shape}")
    faces = np.asarray(faces, dtype=np.int64)
    check_mesh(vertices[0], faces)
    n_frames = len(vertices)
    per_frame = _frame_scalars(scalars, n_frames)
    if per_frame is not None and colour_map is None:
        colour_map = ColourMap.spanning(per_frame)
    base = camera or frontal_camera(
        vertices[0], size, bar_px=0 if colour_map is None else BAR_HEIGHT
    )
    az = np.zeros(n_frames) if azimuth_deg is None else np.asarray(azimuth_deg, dtype=np.float64)
    if az.shape != (n_frames,):
        raise ValueError(f"azimuth_deg must be ({n_frames},) degrees, got shape {az.shape}")
    cameras = [[turntable(base, a + v) for a in az] for v in views_deg]
    settings = dict(size=size, colour_map=colour_map, colour=colour)
    if backend not in ("raster", "vtk"):
        raise ValueError(f"backend must be 'raster' or 'vtk', got {backend!r}")
    if backend == "vtk" and isolate:
        return render_isolated(vertices, faces, per_frame, cameras, settings, progress, threads)
    out = np.empty((len(views_deg), n_frames, size[1], size[0], 3), dtype=np.uint8)
    workers = 1 if backend == "vtk" else min(threads or len(os.sched_getaffinity(0)), n_frames)
    bounds = np.linspace(0, n_frames, max(workers, 1) + 1).round().astype(int)
    shares = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    done = [0] * len(shares)

    def render_share(i: int) -> None:
        frames = shares[i]  # a view of ``out``: the share renders in place

        def counted(n: int, _total: int) -> None:
            done[i] = n
            if progress is not None:
                progress(sum(done), len(views_deg) * n_frames)

        render_frames(
            out[:, frames], vertices[frames], faces,
            None if per_frame is None else per_frame[frames],
            [view[frames] for view in cameras], settings, backend, counted,
        )  # fmt: skip

    # the rasteriser's kernels release the GIL: the frames' shares render side by side
    with ThreadPoolExecutor(len(shares)) as pool:
        list(pool.map(render_share, range(len(shares))))
    return out
