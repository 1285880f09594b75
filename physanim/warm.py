"""Compile the project's numba kernels into numba's on-disk cache ahead of the first run.

A fresh clone has no cache: the first run would compile every kernel it calls (the FEM's take
about 30 s on 2 cores, more than the simulation itself; the demo's rasteriser about 2 s in each
process that renders frames, the face renders' shader as much). ``make setup`` runs ``python
-m physanim.warm`` once after installing, so that the first pipeline run loads them instead.
"""

from __future__ import annotations

import time

import numpy as np

from physanim.capture.raster import rasterize
from physanim.export.animation import frame_normals
from physanim.fem.warm import warm_kernels
from physanim.render.surface import render_surface


def warm_rasterizer() -> float:
    """Rasterise one triangle (compiling or loading the z-buffer kernel); returns seconds."""
    t0 = time.perf_counter()
    triangle = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0]])
    K = np.array([[100.0, 0.0, 10.0], [0.0, 100.0, 10.0], [0.0, 0.0, 1.0]])
    rasterize(triangle, np.array([[0, 1, 2]]), K, (30, 30))
    return time.perf_counter() - t0


def warm_render() -> float:
    """Render one triangle (compiling or loading the face renders' normals and shader
    kernels); returns seconds."""
    t0 = time.perf_counter()
    triangle = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    render_surface(triangle, np.array([[0, 1, 2]]), size=(32, 32))
    return time.perf_counter() - t0


def warm_export() -> float:
    """The normals of one triangle's frames (compiling or loading the export's kernel, 3 s);
    returns seconds."""
    t0 = time.perf_counter()
    triangle = np.array([[[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]]], np.float32)
    frame_normals(triangle, np.array([[0, 1, 2]]))
    return time.perf_counter() - t0


if __name__ == "__main__":
    fem = warm_kernels()
    raster = warm_rasterizer()
    render = warm_render()
    export = warm_export()
    print(
        "numba kernels compiled (cache): FEM "
        + ", ".join(f"{k} factor {v:.1f} s" for k, v in fem.items())
        + f"; demo rasteriser {raster:.1f} s; face renders {render:.1f} s; export normals "
        f"{export:.1f} s"
    )
