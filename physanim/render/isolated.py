"""VTK renders of a sequence in a separate Python process, and that worker process.

Robustness: VTK's OpenGL context is a process-wide native resource and a crash in it kills
the caller.  A segfault was reported with pymeshlab imported in the same process; with VTK
9.7.2/EGL it did not reproduce whatever the import order (pymeshlab, open3d, pytetwild
before or after pyvista, meshes loaded, several plotters), but VTK does segfault (SIGSEGV,
no Python exception) whenever it cannot create a GL context, e.g. when it picks OSMesa and
libOSMesa is not installed (``VTK_DEFAULT_OPENGL_WINDOW=vtkOSOpenGLRenderWindow`` here).
``physanim.render.face.render_sequence`` with ``backend="vtk"`` and ``isolate=True``
(default) therefore renders in a separate Python process (``python -m
physanim.render.isolated``, importing numpy, matplotlib, pyvista and the renderer's modules; no
``__main__`` guard needed in the caller), and raises RuntimeError if that worker dies or fails.

Protocol: the inputs go in an .npz (arrays and a JSON ``meta``), the frames come back in a
memory-mapped .npy, and the worker prints one ``@physanim-frame K`` line per frame rendered
(K: the images done, all views of the frames so far).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from physanim.cameras import Camera
from physanim.render.colours import ColourMap
from physanim.render.surface import render_frames

_PROGRESS_TAG = "@physanim-frame "


def render_isolated(
    vertices, faces, per_frame, cameras, settings, progress, threads: int | None = None
) -> np.ndarray:
    """Run ``python -m physanim.render.isolated`` on the images (arguments as in
    :func:`.surface.render_frames`; inputs in an .npz, output (V, T, H, W, 3) in a
    memory-mapped .npy); ``threads``: the software rasteriser's (Mesa llvmpipe) threads
    (None: its default, one per core); raises RuntimeError if the worker fails or dies."""
    n_views, n_frames = len(cameras), len(vertices)
    n_images = n_views * n_frames
    width, height = settings["size"]
    with tempfile.TemporaryDirectory(prefix=f"physanim-render-{os.getpid()}-") as tmp:
        job, result = Path(tmp) / "job.npz", Path(tmp) / "frames.npy"
        cmap = settings["colour_map"]
        np.savez(
            job,
            vertices=np.asarray(vertices, dtype=np.float32),  # half the bytes; ample for pixels
            faces=faces,
            scalars=np.zeros((0,)) if per_frame is None else per_frame,
            cameras=np.array(
                [
                    [[*c.position, *c.focal_point, *c.view_up, c.view_angle] for c in v]
                    for v in cameras
                ]
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
            result, mode="w+", dtype=np.uint8, shape=(n_views, n_frames, height, width, 3)
        )
        del out
        env = dict(os.environ)
        if threads is not None:
            env["LP_NUM_THREADS"] = str(threads)
        if not env.get("DISPLAY"):
            env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # no X probing
        with subprocess.Popen(
            [sys.executable, "-m", "physanim.render.isolated", str(job), str(result)],
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
                        progress(done, n_images)
            err = proc.stderr.read()
        if proc.returncode != 0 or done != n_images:
            tail = "\n".join(re.sub(r"\x1b\[[0-9;]*m", "", err).strip().splitlines()[-3:])
            raise RuntimeError(
                f"VTK render worker exited with code {proc.returncode} after {done}/{n_images} "
                f"images: {tail}"
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
    cameras = [
        [Camera(tuple(c[0:3]), tuple(c[3:6]), tuple(c[6:9]), float(c[9])) for c in view]
        for view in data["cameras"]
    ]
    scalars = data["scalars"] if cmap is not None else None
    settings = dict(size=tuple(meta["size"]), colour_map=cmap, colour=tuple(meta["colour"]))
    out = np.load(result, mmap_mode="r+")
    render_frames(
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
