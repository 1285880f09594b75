"""Alembic (.abc) of an exported USD, written by Blender's Python module ``bpy`` (optional).

No Python binding of the Alembic library is on PyPI ('alembic' there is SQLAlchemy's
migration tool) or in Debian; Blender's exporter is one a technical artist knows. ``bpy`` is
large (~370 MB) and optional (``pip install '.[blender]'``), and one Blender instance lives
in a process, holding global state: each conversion runs Blender in a child process of this
interpreter (``python -m physanim.export.alembic``). Blender imports the USD (its Y-up turned
to Blender's Z-up by a root rotation) and its Alembic exporter writes Y-up again, in metres,
one sample per frame at the animation's frame rate.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

from physanim.export import require


def write_alembic(usd: Path, path: Path, fps: float, frames: int, timeout_s: float = 600) -> Path:
    """Write the Alembic ``path`` of the USD file ``usd`` (frames 0 .. ``frames``-1 at ``fps``
    frames/s) through Blender in a child process and return ``path``. RuntimeError with
    Blender's last output when it fails or ``bpy`` is missing."""
    require("bpy")
    cmd = [sys.executable, "-m", __name__, str(usd), str(path), repr(float(fps)), str(frames)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    if done.returncode != 0 or not Path(path).is_file():
        tail = (done.stdout + done.stderr)[-2000:]
        raise RuntimeError(f"Blender's Alembic export of {usd} failed ({done.returncode}): {tail}")
    return Path(path)


def set_frame_rate(scene: Any, fps: float) -> None:
    """The frame rate ``fps`` frames/s on Blender's ``scene`` (a bpy.types.Scene): an
    integer over a base."""
    rounded = max(1, round(fps))
    scene.render.fps = rounded
    scene.render.fps_base = rounded / fps


def _convert(usd: str, path: str, fps: float, frames: int) -> None:
    """Inside Blender: an empty scene at ``fps``, the USD imported, the Alembic exported."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=usd)
    scene = bpy.context.scene
    set_frame_rate(scene, fps)
    scene.frame_start, scene.frame_end = 0, frames - 1
    bpy.ops.wm.alembic_export(
        filepath=path, start=0, end=frames - 1, normals=False, uvs=False, face_sets=False,
        export_hair=False, export_particles=False, evaluation_mode="RENDER",
    )  # fmt: skip


if __name__ == "__main__":
    _convert(sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]))
