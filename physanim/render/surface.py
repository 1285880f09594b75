"""Offscreen render of one face surface, frame after frame: lit, smooth-shaded skin or a
colour map with its labelled colour bar, through either backend (same camera model, same
colour mapping, same bar, same lighting): ``"raster"`` (:mod:`.raster_backend`, the project's
own) or ``"vtk"`` (:mod:`.vtk_backend`). In-process; sequences:
:func:`physanim.render.face.render_sequence`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from physanim.cameras import Camera, frontal_camera
from physanim.mesh.topology import vertex_normals
from physanim.render.colours import BAR_HEIGHT, SKIN, ColourMap, colour_bar
from physanim.render.raster_backend import render_raster
from physanim.render.vtk_backend import VtkView


def check_mesh(vertices: np.ndarray, faces: np.ndarray) -> None:
    """Raise ValueError naming the array unless vertices (N, 3) and faces (M, 3) index them."""
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must be (N, 3) metres, got shape {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must be (M, 3) vertex indices, got shape {faces.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError(f"faces index vertices 0..{len(vertices) - 1}; got {faces.max()}")


def scalar_site(scalars: np.ndarray, n_vertices: int, n_faces: int) -> str:
    """'point' or 'cell' for (N,) or (M,) scalars; raises on any other length."""
    if scalars.shape == (n_vertices,):
        return "point"
    if scalars.shape == (n_faces,):
        return "cell"
    raise ValueError(
        f"scalars must be per vertex ({n_vertices},) or per face ({n_faces},); "
        f"got shape {scalars.shape}"
    )


class SurfaceRenderer:
    """Renders one mesh topology, frame after frame, at a fixed image size.

    ``faces`` (M, 3) int; ``size`` = (W, H) pixels of the output image (a colour bar, when
    ``colour_map`` is given, takes the bottom ``BAR_HEIGHT`` rows); ``colour`` sRGB 0-1 of
    the skin when no scalars are drawn.  Use as a context manager, or call ``close``.
    """

    def __init__(
        self,
        faces: np.ndarray,
        n_vertices: int,
        *,
        size: tuple[int, int] = (480, 640),
        colour_map: ColourMap | None = None,
        colour: tuple[float, float, float] = SKIN,
        backend: Literal["raster", "vtk"] = "raster",
    ) -> None:
        self.faces = np.asarray(faces, dtype=np.int64)
        self.n_vertices = n_vertices
        self.size = size
        self.colour_map = colour_map
        self.colour = np.asarray(colour, dtype=np.float64)
        self.backend = backend
        width, height = size
        self.bar = colour_bar(colour_map, width) if colour_map is not None else None
        self.view_size = (width, height - (BAR_HEIGHT if self.bar is not None else 0))
        if self.view_size[1] < 16:
            raise ValueError(f"size {size} (W, H) px leaves no room for the view")
        self._vtk = VtkView(self.faces, self.view_size, self.colour) if backend == "vtk" else None

    def __enter__(self) -> SurfaceRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the VTK render window (no-op for the raster backend)."""
        if self._vtk is not None:
            self._vtk.close()

    def render(
        self, vertices: np.ndarray, camera: Camera, scalars: np.ndarray | None = None
    ) -> np.ndarray:
        """(H, W, 3) uint8 image of the mesh at ``vertices`` (N, 3) m; ``scalars`` (N,) or
        (M,) in the colour map's unit (required iff the renderer has a colour map)."""
        return self.render_views(vertices, [camera], scalars)[0]

    def render_views(
        self, vertices: np.ndarray, cameras: Sequence[Camera], scalars: np.ndarray | None = None
    ) -> list[np.ndarray]:
        """One (H, W, 3) uint8 image per camera of the mesh at ``vertices`` (N, 3) m, shaded
        and uploaded once; ``scalars`` as in :meth:`render`."""
        vertices = np.asarray(vertices, dtype=np.float64)
        check_mesh(vertices, self.faces)
        if len(vertices) != self.n_vertices:
            raise ValueError(f"vertices: expected ({self.n_vertices}, 3), got {vertices.shape}")
        rgb, site = None, "point"
        if (scalars is None) != (self.colour_map is None):
            raise ValueError("pass scalars exactly when the renderer was built with a colour_map")
        if scalars is not None:
            scalars = np.asarray(scalars)
            site = scalar_site(scalars, len(vertices), len(self.faces))
            rgb = self.colour_map.colours(scalars)
        normals = vertex_normals(vertices, self.faces)
        if self._vtk is not None:
            views = self._vtk.render(vertices, normals, rgb, site, cameras)
        else:
            views = [
                render_raster(
                    vertices, normals, self.faces, rgb, site, c, self.view_size, self.colour
                )
                for c in cameras
            ]
        return [v if self.bar is None else np.concatenate([v, self.bar], axis=0) for v in views]


def render_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    scalars: np.ndarray | None = None,
    colour_map: ColourMap | None = None,
    camera: Camera | None = None,
    size: tuple[int, int] = (480, 640),
    colour: tuple[float, float, float] = SKIN,
    backend: Literal["raster", "vtk"] = "raster",
) -> np.ndarray:
    """One (H, W, 3) uint8 image of a mesh: ``vertices`` (N, 3) m, ``faces`` (M, 3); optional
    ``scalars`` (N,) or (M,) drawn with ``colour_map`` (default: unlabelled, over the range); camera
    defaults to ``frontal_camera(vertices)``.  In-process; for sequences use
    ``render_sequence``."""
    if scalars is not None and colour_map is None:
        colour_map = ColourMap.spanning(scalars)
    if camera is None:
        camera = frontal_camera(vertices, size, bar_px=0 if colour_map is None else BAR_HEIGHT)
    with SurfaceRenderer(
        faces, len(vertices), size=size, colour_map=colour_map, colour=colour, backend=backend
    ) as renderer:
        return renderer.render(vertices, camera, scalars)


def render_frames(out, vertices, faces, per_frame, cameras, settings, backend, progress) -> None:
    """Render frame t of ``vertices`` (T, N, 3) m (and of the ``per_frame`` scalars) seen by
    ``cameras[v][t]`` into ``out[v, t]`` ((V, T, H, W, 3) uint8) with one renderer."""
    n_views, n_frames = len(cameras), len(vertices)
    with SurfaceRenderer(faces, vertices.shape[1], **settings, backend=backend) as renderer:
        for t in range(n_frames):
            s = None if per_frame is None else per_frame[t]
            views = renderer.render_views(vertices[t], [c[t] for c in cameras], s)
            for v, image in enumerate(views):
                out[v, t] = image
            if progress is not None:
                progress((t + 1) * n_views, n_views * n_frames)
