"""Run inside Blender's interpreter (``physanim.export.blender``), standalone: it imports
only ``bpy`` and the standard library, as that interpreter has no physanim.

    python blender_scene.py USD ABC FPS FRAMES

writes the Alembic ABC of the USD file at FPS frames/s, frames 0 .. FRAMES-1. The tests'
Blender probe imports :func:`set_frame_rate` from here.
"""

from __future__ import annotations

import sys
from typing import Any


def set_frame_rate(scene: Any, fps: float) -> None:
    """The frame rate ``fps`` frames/s on Blender's ``scene`` (a bpy.types.Scene): an
    integer over a base."""
    rounded = max(1, round(fps))
    scene.render.fps = rounded
    scene.render.fps_base = rounded / fps


def usd_to_alembic(usd: str, path: str, fps: float, frames: int) -> None:
    """An empty scene at ``fps``, the USD imported, the Alembic exported."""
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
    usd_to_alembic(sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]))
