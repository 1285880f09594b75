"""Offscreen renders of a face surface: lit, smooth-shaded skin or a colour map with a
labelled colour bar, seen by a fixed camera (optionally a turntable).

Two backends give the same framing (same camera model, same colour mapping, same bar):
- ``"vtk"``: pyvista/VTK offscreen (EGL or OSMesa, no display needed); Gouraud-shaded, lit by
  VTK's light kit.  One plotter per sequence, points/normals/colours updated in place.
- ``"numpy"``: the project's vectorised z-buffer rasteriser (``physanim.capture.raster``)
  with Lambert + Blinn-Phong headlight shading; no OpenGL at all.

Robustness: VTK's OpenGL context is a process-wide native resource and a crash in it kills
the caller.  A segfault was reported with pymeshlab imported in the same process; with VTK
9.7.2/EGL it did not reproduce whatever the import order (pymeshlab, open3d, pytetwild
before or after pyvista, meshes loaded, several plotters), but VTK does segfault (SIGSEGV,
no Python exception) whenever it cannot create a GL context, e.g. when it picks OSMesa and
libOSMesa is not installed (``VTK_DEFAULT_OPENGL_WINDOW=vtkOSOpenGLRenderWindow`` here).
``render_sequence`` with ``isolate=True`` (default) therefore renders in a separate Python
process (``python -m physanim.render.face``; importing only numpy, matplotlib, pyvista; no
``__main__`` guard needed in the caller); if that worker dies or fails, ``backend="auto"``
re-renders the sequence with the numpy backend and warns.  ``render_surface`` and
``SurfaceRenderer`` render in-process (for single images and tests).

Frames: actor frame (+x actor's left, +y up, +z out of the face), so the frontal camera sits
on +z and the actor's left appears on the image's right, as in a photograph.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import Normalize
from matplotlib.figure import Figure as MplFigure

from physanim.capture.raster import rasterize
from physanim.mesh.topology import vertex_normals

#: default skin albedo, sRGB 0-1
SKIN = (0.89, 0.72, 0.62)
BACKGROUND = (1.0, 1.0, 1.0)
#: height of the colour-bar strip under the view, pixels
BAR_HEIGHT = 64

Backend = Literal["auto", "vtk", "numpy"]
_PROGRESS_TAG = "@physanim-frame "


@dataclass(frozen=True)
class Camera:
    """Perspective camera: ``position``, ``focal_point`` (3,) m, ``view_up`` (3,) unit,
    ``view_angle`` vertical field of view in degrees (VTK's convention)."""

    position: tuple[float, float, float]
    focal_point: tuple[float, float, float]
    view_up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    view_angle: float = 20.0


@dataclass(frozen=True)
class ColourMap:
    """How scalars become colours: matplotlib ``cmap`` name over ``clim`` (lo, hi) in the
    scalars' unit, bar titled ``label`` (e.g. "displacement (mm)", "von Mises stress (kPa)";
    the default map starts light so that shading stays visible at zero).  With
    ``categories`` the scalars are integer labels 0..len-1 (e.g. tissue regions) drawn with
    a qualitative map and a legend of the category names."""

    label: str
    clim: tuple[float, float] = (0.0, 1.0)
    cmap: str = "YlOrRd"
    categories: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if self.categories is None and not self.clim[1] > self.clim[0]:
            raise ValueError(f"ColourMap {self.label!r}: clim must be (lo, hi) with hi > lo")
        if self.cmap not in colormaps:
            raise ValueError(f"ColourMap {self.label!r}: unknown matplotlib cmap {self.cmap!r}")

    @classmethod
    def spanning(cls, scalars: np.ndarray, label: str = "") -> ColourMap:
        """A map over the range of ``scalars`` (widened to 1 unit if they are constant)."""
        lo, hi = float(np.min(scalars)), float(np.max(scalars))
        return cls(label=label, clim=(lo, hi if hi > lo else lo + 1.0))

    def colours(self, scalars: np.ndarray) -> np.ndarray:
        """(K,) scalars -> (K, 3) uint8 sRGB."""
        if self.categories is not None:
            table = _category_colours(len(self.categories))
            idx = np.clip(np.asarray(scalars).astype(np.int64), 0, len(self.categories) - 1)
            rgb = table[idx]
        else:
            lo, hi = self.clim
            rgb = colormaps[self.cmap](Normalize(lo, hi, clip=True)(scalars))[:, :3]
        return np.round(255 * rgb).astype(np.uint8)


def _category_colours(n: int) -> np.ndarray:
    """(n, 3) float distinct colours (tab10, then tab20)."""
    base = colormaps["tab10" if n <= 10 else "tab20"]
    return np.array([base(i % base.N)[:3] for i in range(n)])


def frontal_camera(
    neutral: np.ndarray,
    size: tuple[int, int] = (480, 640),
    *,
    margin: float = 1.08,
    view_angle: float = 20.0,
    bar: bool = False,
) -> Camera:
    """Camera on +z looking at the centre of the bounding box of ``neutral`` (N, 3) m, at the
    distance where the box (times ``margin``) just fits the view of ``size`` = (W, H) pixels
    (less the colour-bar strip if ``bar``).  Share it over all frames of a sequence."""
    v = np.asarray(neutral, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo) * margin
    width, height = size
    aspect = width / (height - (BAR_HEIGHT if bar else 0))
    tan_half = np.tan(np.radians(view_angle) / 2)
    dist = max(half[1], half[0] / aspect) / tan_half + half[2]
    return Camera(
        position=tuple(centre + [0.0, 0.0, dist]),
        focal_point=tuple(centre),
        view_angle=view_angle,
    )


def turntable(camera: Camera, azimuth_deg: float) -> Camera:
    """``camera`` rotated by ``azimuth_deg`` about its view-up axis through the focal point
    (positive: the camera moves towards +x, i.e. shows more of the actor's left)."""
    up = np.asarray(camera.view_up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    focal = np.asarray(camera.focal_point, dtype=np.float64)
    r = np.asarray(camera.position) - focal
    a = np.radians(azimuth_deg)
    # Rodrigues rotation of r about up.
    rot = r * np.cos(a) + np.cross(up, r) * np.sin(a) + up * (up @ r) * (1 - np.cos(a))
    return replace(camera, position=tuple(focal + rot))


def colour_bar(colour_map: ColourMap, width: int, height: int = BAR_HEIGHT) -> np.ndarray:
    """(height, width, 3) uint8 strip: a horizontal labelled colour bar, or a legend of the
    categories (matplotlib, Agg)."""
    dpi = 100
    fig = MplFigure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=BACKGROUND)
    if colour_map.categories is None:
        ax = fig.add_axes((0.08, 0.62, 0.84, 0.26))
        lo, hi = colour_map.clim
        ramp = np.linspace(lo, hi, 256)[None, :]
        ax.imshow(ramp, aspect="auto", cmap=colour_map.cmap, extent=(lo, hi, 0, 1))
        ax.set_yticks([])
        ax.tick_params(labelsize=8, length=3, pad=1)
        ax.set_xlabel(colour_map.label, fontsize=9, labelpad=1)
    else:
        from matplotlib.patches import Patch

        colours = _category_colours(len(colour_map.categories))
        handles = [
            Patch(fc=c, ec="0.3", label=n)
            for c, n in zip(colours, colour_map.categories, strict=True)
        ]
        fig.legend(
            handles=handles,
            loc="center",
            ncol=-(-len(handles) // -(-len(handles) // max(1, width // 90))),  # balanced rows
            fontsize=8,
            frameon=False,
            title=colour_map.label,
            title_fontsize=9,
            handlelength=1.2,
            columnspacing=0.8,
        )
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def _check_mesh(vertices: np.ndarray, faces: np.ndarray) -> None:
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must be (N, 3) metres, got shape {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must be (M, 3) vertex indices, got shape {faces.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError(f"faces index vertices 0..{len(vertices) - 1}; got {faces.max()}")


def _scalar_site(scalars: np.ndarray, n_vertices: int, n_faces: int) -> str:
    """'point' or 'cell' for (N,) or (M,) scalars; raises on any other length."""
    if scalars.shape == (n_vertices,):
        return "point"
    if scalars.shape == (n_faces,):
        return "cell"
    raise ValueError(
        f"scalars must be per vertex ({n_vertices},) or per face ({n_faces},); "
        f"got shape {scalars.shape}"
    )


def _view_matrix(camera: Camera) -> np.ndarray:
    """(3, 4) world -> OpenCV camera frame (+x right, +y down, +z forward) [R | t]."""
    pos = np.asarray(camera.position, dtype=np.float64)
    forward = np.asarray(camera.focal_point) - pos
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.view_up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rot = np.stack([right, down, forward])
    return np.concatenate([rot, -(rot @ pos)[:, None]], axis=1)


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
        backend: Literal["vtk", "numpy"] = "vtk",
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
        self._plotter = None
        self._mesh = None

    def __enter__(self) -> SurfaceRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the VTK render window (no-op for the numpy backend)."""
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None

    def render(
        self, vertices: np.ndarray, camera: Camera, scalars: np.ndarray | None = None
    ) -> np.ndarray:
        """(H, W, 3) uint8 image of the mesh at ``vertices`` (N, 3) m; ``scalars`` (N,) or
        (M,) in the colour map's unit (required iff the renderer has a colour map)."""
        vertices = np.asarray(vertices, dtype=np.float64)
        _check_mesh(vertices, self.faces)
        if len(vertices) != self.n_vertices:
            raise ValueError(f"vertices: expected ({self.n_vertices}, 3), got {vertices.shape}")
        rgb, site = None, "point"
        if (scalars is None) != (self.colour_map is None):
            raise ValueError("pass scalars exactly when the renderer was built with a colour_map")
        if scalars is not None:
            scalars = np.asarray(scalars)
            site = _scalar_site(scalars, len(vertices), len(self.faces))
            rgb = self.colour_map.colours(scalars)
        normals = vertex_normals(vertices, self.faces)
        if self.backend == "vtk":
            view = self._render_vtk(vertices, normals, rgb, site, camera)
        else:
            view = self._render_numpy(vertices, normals, rgb, site, camera)
        return view if self.bar is None else np.concatenate([view, self.bar], axis=0)

    def _render_vtk(self, vertices, normals, rgb, site, camera: Camera) -> np.ndarray:
        import pyvista as pv

        if self._plotter is None:
            pv.OFF_SCREEN = True
            cells = np.hstack([np.full((len(self.faces), 1), 3), self.faces]).ravel()
            mesh = pv.PolyData(vertices.copy(), cells)
            mesh.point_data["Normals"] = normals
            mesh.point_data.active_normals_name = "Normals"
            plotter = pv.Plotter(off_screen=True, window_size=self.view_size)
            plotter.render_window.SetMultiSamples(0)  # MSAA is 4-5x slower on llvmpipe
            plotter.set_background(BACKGROUND)
            style = dict(ambient=0.15, diffuse=0.85, specular=0.15, specular_power=20.0)
            if rgb is None:
                plotter.add_mesh(mesh, color=tuple(self.colour), interpolation="gouraud", **style)
            else:
                data = mesh.point_data if site == "point" else mesh.cell_data
                data["rgb"] = rgb
                plotter.add_mesh(mesh, scalars="rgb", rgb=True, interpolation="gouraud", **style)
            self._plotter, self._mesh = plotter, mesh
        mesh = self._mesh
        mesh.points[:] = vertices
        mesh.point_data["Normals"][:] = normals
        if rgb is not None:
            (mesh.point_data if site == "point" else mesh.cell_data)["rgb"][:] = rgb
        mesh.Modified()
        cam = self._plotter.camera
        cam.position, cam.focal_point, cam.up = camera.position, camera.focal_point, camera.view_up
        cam.view_angle = camera.view_angle
        self._plotter.reset_camera_clipping_range()
        self._plotter.render()
        return np.ascontiguousarray(self._plotter.screenshot(return_img=True)[..., :3])

    def _render_numpy(self, vertices, normals, rgb, site, camera: Camera) -> np.ndarray:
        width, height = self.view_size
        view = _view_matrix(camera)
        cam_pts = vertices @ view[:, :3].T + view[:, 3]
        f = (height / 2) / np.tan(np.radians(camera.view_angle) / 2)
        K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
        raster = rasterize(cam_pts, self.faces, K, (height, width), near=1e-3)
        mask = raster.mask
        n = raster.interpolate(normals @ view[:, :3].T, self.faces)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        pts = raster.interpolate(cam_pts, self.faces)
        to_eye = -pts / np.linalg.norm(pts, axis=1, keepdims=True)
        n *= np.where((n * to_eye).sum(axis=1) < 0, -1.0, 1.0)[:, None]  # two-sided
        key = np.array([-0.35, -0.45, -1.0])
        key /= np.linalg.norm(key)  # upper-left light, camera frame
        diffuse = 0.6 * np.clip((n * to_eye).sum(axis=1), 0, 1) + 0.3 * np.clip(n @ key, 0, 1)
        half = to_eye + key
        half /= np.linalg.norm(half, axis=1, keepdims=True)
        spec = 0.12 * np.clip((n * half).sum(axis=1), 0, 1) ** 20
        if rgb is None:
            albedo = np.broadcast_to(self.colour, (mask.sum(), 3))
        elif site == "cell":
            albedo = rgb[raster.face[mask]] / 255.0
        else:
            albedo = raster.interpolate(rgb / 255.0, self.faces)
        shade = albedo * (0.15 + diffuse)[:, None] + spec[:, None]
        image = np.empty((height, width, 3))
        image[:] = BACKGROUND
        image[mask] = np.clip(shade, 0, 1)
        return np.round(255 * image).astype(np.uint8)


def render_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    scalars: np.ndarray | None = None,
    colour_map: ColourMap | None = None,
    camera: Camera | None = None,
    size: tuple[int, int] = (480, 640),
    colour: tuple[float, float, float] = SKIN,
    backend: Literal["vtk", "numpy"] = "vtk",
) -> np.ndarray:
    """One (H, W, 3) uint8 image of a mesh: ``vertices`` (N, 3) m, ``faces`` (M, 3); optional
    ``scalars`` (N,) or (M,) drawn with ``colour_map`` (default: unlabelled, over the range); camera
    defaults to ``frontal_camera(vertices)``.  In-process; for sequences use
    ``render_sequence``."""
    if scalars is not None and colour_map is None:
        colour_map = ColourMap.spanning(scalars)
    if camera is None:
        camera = frontal_camera(vertices, size, bar=colour_map is not None)
    with SurfaceRenderer(
        faces, len(vertices), size=size, colour_map=colour_map, colour=colour, backend=backend
    ) as renderer:
        return renderer.render(vertices, camera, scalars)


# --- sequences, optionally in an isolated worker process ------------------------------------


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
    backend: Backend = "auto",
    isolate: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Render an animated mesh: ``vertices`` (T, N, 3) m, ``faces`` (M, 3) -> (T, H, W, 3)
    uint8, ``size`` = (W, H) px.

    ``scalars``: (N,)/(M,) fixed (e.g. region labels) or (T, N)/(T, M) per frame (e.g.
    displacement in mm, von Mises stress in kPa), drawn with ``colour_map`` (fixed ``clim``
    so colours are comparable over frames).  ``camera`` defaults to the frontal camera of
    frame 0, shared by all frames; ``azimuth_deg`` (T,) turns it per frame (turntable).
    ``backend``: "vtk", "numpy" or "auto" (vtk, falling back to numpy if VTK fails);
    ``isolate`` runs VTK in a separate Python process (see the module docstring).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.ndim != 3 or vertices.shape[2] != 3:
        raise ValueError(f"vertices must be (T, N, 3) metres, got shape {vertices.shape}")
    faces = np.asarray(faces, dtype=np.int64)
    _check_mesh(vertices[0], faces)
    n_frames = len(vertices)
    per_frame = _frame_scalars(scalars, n_frames)
    if per_frame is not None and colour_map is None:
        colour_map = ColourMap.spanning(per_frame)
    base = camera or frontal_camera(vertices[0], size, bar=colour_map is not None)
    if azimuth_deg is None:
        cameras = [base] * n_frames
    else:
        az = np.asarray(azimuth_deg, dtype=np.float64)
        if az.shape != (n_frames,):
            raise ValueError(f"azimuth_deg must be ({n_frames},) degrees, got shape {az.shape}")
        cameras = [turntable(base, a) for a in az]
    settings = dict(size=size, colour_map=colour_map, colour=colour)
    if backend in ("auto", "vtk") and isolate:
        try:
            return _render_isolated(vertices, faces, per_frame, cameras, settings, progress)
        except RuntimeError as exc:
            if backend == "vtk":
                raise
            warnings.warn(f"{exc}; using the numpy rasteriser", RuntimeWarning, stacklevel=2)
            backend = "numpy"
    out = np.empty((n_frames, size[1], size[0], 3), dtype=np.uint8)
    _render_into(out, vertices, faces, per_frame, cameras, settings, backend, progress)
    return out


def _render_into(out, vertices, faces, per_frame, cameras, settings, backend, progress) -> None:
    """Render every frame into ``out`` (T, H, W, 3) uint8 with one renderer."""
    chosen = "vtk" if backend == "auto" else backend
    with SurfaceRenderer(faces, vertices.shape[1], **settings, backend=chosen) as renderer:
        for t in range(len(vertices)):
            s = None if per_frame is None else per_frame[t]
            out[t] = renderer.render(vertices[t], cameras[t], s)
            if progress is not None:
                progress(t + 1, len(vertices))


def _render_isolated(vertices, faces, per_frame, cameras, settings, progress) -> np.ndarray:
    """Run ``python -m physanim.render.face`` on the frames (inputs in an .npz, output in a
    memory-mapped .npy); raises RuntimeError if the worker fails or dies."""
    n_frames = len(vertices)
    width, height = settings["size"]
    with tempfile.TemporaryDirectory(prefix=f"physanim-render-{os.getpid()}-") as tmp:
        job, result = Path(tmp) / "job.npz", Path(tmp) / "frames.npy"
        cmap = settings["colour_map"]
        np.savez(
            job,
            vertices=vertices,
            faces=faces,
            scalars=np.zeros((0,)) if per_frame is None else per_frame,
            cameras=np.array(
                [[*c.position, *c.focal_point, *c.view_up, c.view_angle] for c in cameras]
            ),
            meta=json.dumps(
                {
                    "size": list(settings["size"]),
                    "colour": list(settings["colour"]),
                    "colour_map": None if cmap is None else asdict(cmap),
                }
            ),
        )
        out = np.lib.format.open_memmap(
            result, mode="w+", dtype=np.uint8, shape=(n_frames, height, width, 3)
        )
        del out
        env = dict(os.environ)
        if not env.get("DISPLAY"):
            env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # no X probing
        with subprocess.Popen(
            [sys.executable, "-m", "physanim.render.face", str(job), str(result)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        ) as proc:
            done = 0
            for line in proc.stdout:  # other output from VTK/pyvista is ignored
                if line.startswith(_PROGRESS_TAG):
                    done = int(line[len(_PROGRESS_TAG) :])
                    if progress is not None:
                        progress(done, n_frames)
            err = proc.stderr.read()
        if proc.returncode != 0 or done != n_frames:
            tail = "\n".join(re.sub(r"\x1b\[[0-9;]*m", "", err).strip().splitlines()[-3:])
            raise RuntimeError(
                f"VTK render worker exited with code {proc.returncode} after {done}/{n_frames} "
                f"frames: {tail}"
            )
        return np.load(result)


def _worker_main(job: str, result: str) -> None:
    """Entry point of the isolated worker: render ``job`` (.npz) into ``result`` (.npy)."""
    data = np.load(job)
    meta = json.loads(str(data["meta"]))
    cmap = meta["colour_map"]
    if cmap is not None:
        cats = cmap["categories"]
        cmap = ColourMap(
            label=cmap["label"],
            clim=tuple(cmap["clim"]),
            cmap=cmap["cmap"],
            categories=None if cats is None else tuple(cats),
        )
    cams = data["cameras"]
    cameras = [Camera(tuple(c[0:3]), tuple(c[3:6]), tuple(c[6:9]), float(c[9])) for c in cams]
    scalars = data["scalars"] if cmap is not None else None
    settings = dict(size=tuple(meta["size"]), colour_map=cmap, colour=tuple(meta["colour"]))
    out = np.load(result, mmap_mode="r+")
    _render_into(
        out,
        data["vertices"],
        data["faces"],
        scalars,
        cameras,
        settings,
        "vtk",
        lambda done, total: print(f"{_PROGRESS_TAG}{done}", flush=True),
    )
    out.flush()


if __name__ == "__main__":
    _worker_main(*sys.argv[1:3])
