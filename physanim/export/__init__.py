"""Animated meshes as files that other tools read: USD, glTF 2.0 binary and (through Blender)
Alembic.

``animation``: :class:`MeshAnimation`, the vertex positions of a triangle mesh per frame at a
frame rate, with its per-frame normals; ``usd``: a USD stage with point time samples;
``gltf``: a morph-target basis of the animation (its principal components) with animated
weights, written and decoded as .glb; ``alembic``: Alembic through Blender's Python module
``bpy`` in a child process of its own interpreter (optional, ``blender``: ``make setup-blender``).

Every file is in metres, +y up, right-handed (the actor frame: +x the actor's left, +z out of
the face), frame i at i / fps seconds.
"""

from __future__ import annotations

import importlib.util

#: The optional Python modules of the exporters -> the extra of pyproject.toml installing them.
EXTRAS = {"pxr": "export", "pygltflib": "export"}


def missing(*modules: str) -> list[str]:
    """Those of ``modules`` that cannot be imported here (found without importing them)."""
    return [m for m in modules if importlib.util.find_spec(m) is None]


def require(*modules: str) -> None:
    """RuntimeError naming the pip extras to install when any of ``modules`` is missing."""
    absent = missing(*modules)
    if absent:
        extras = ",".join(sorted({EXTRAS[m] for m in absent}))
        raise RuntimeError(f"export needs {', '.join(absent)}: pip install '.[{extras}]'")
