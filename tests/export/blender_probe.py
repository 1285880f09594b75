"""Run by the Blender tests in a child process of Blender's interpreter: open a USD, Alembic
or glTF file in Blender at a frame rate, step its frames and save the mesh's world-space
vertex positions, turned from Blender's Z-up back to the files' Y-up, as (T, N, 3) float64 m
in a .npy file.

    python tests/export/blender_probe.py FILE FPS FRAMES OUT.npy
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np

# Blender's interpreter has no physanim: the one helper comes from its standalone script
sys.path.insert(0, str(Path(__file__).parents[2] / "physanim" / "export"))
from blender_scene import set_frame_rate  # noqa: E402

IMPORTERS = {
    ".usdc": bpy.ops.wm.usd_import,
    ".usda": bpy.ops.wm.usd_import,
    ".abc": bpy.ops.wm.alembic_import,
    ".glb": bpy.ops.import_scene.gltf,
}


def positions(path: Path, fps: float, frames: int) -> np.ndarray:
    """(frames, N, 3) m, Y-up: the one mesh of ``path`` at frames 0 .. frames-1."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    set_frame_rate(scene, fps)  # before the import: the glTF importer keys frames by it
    IMPORTERS[path.suffix](filepath=str(path))
    (obj,) = [o for o in scene.objects if o.type == "MESH"]
    out = []
    for t in range(frames):
        scene.frame_set(t)
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        mesh = evaluated.to_mesh()
        co = np.empty(3 * len(mesh.vertices), np.float32)
        mesh.vertices.foreach_get("co", co)
        world = np.array(evaluated.matrix_world)
        p = co.reshape(-1, 3).astype(np.float64) @ world[:3, :3].T + world[:3, 3]
        out.append(p[:, [0, 2, 1]] * [1.0, 1.0, -1.0])  # Blender's (x, -z, y) -> (x, y, z)
        evaluated.to_mesh_clear()
    return np.stack(out)


if __name__ == "__main__":
    file, fps, frames, out = sys.argv[1:5]
    np.save(out, positions(Path(file), float(fps), int(frames)))
