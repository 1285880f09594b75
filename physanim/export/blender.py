"""Which Python interpreter runs Blender's module ``bpy`` for the Alembic writer and the
Blender tests.

``bpy`` is large (~370 MB) and pins its own numpy (bpy 5.0: numpy 1.26, which this project's
OpenCV and Zarr forbid), so it lives in an interpreter of its own, and Blender only ever runs
in a child process: one Blender instance per process holds global state anyway. In order:
the interpreter named by ``PHYSANIM_BLENDER_PYTHON``; this interpreter, where it has ``bpy``;
``.venv-blender/bin/python`` beside this interpreter's virtual environment (what
``make setup-blender`` creates).
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

#: The environment variable naming an interpreter with ``bpy``.
ENV = "PHYSANIM_BLENDER_PYTHON"
#: How to get one, for error messages.
HOW = f"make setup-blender (a .venv-blender with pip's bpy), or set {ENV} to a Python with bpy"


def blender_python() -> Path | None:
    """The interpreter with ``bpy`` (see the module docstring), or None when there is none."""
    named = os.environ.get(ENV)
    if named:
        return Path(named)
    if importlib.util.find_spec("bpy") is not None:
        return Path(sys.executable)
    beside = Path(sys.prefix).parent / ".venv-blender" / "bin" / "python"
    return beside if beside.is_file() else None


def require_blender() -> Path:
    """:func:`blender_python`, or RuntimeError saying how to get one."""
    found = blender_python()
    if found is None:
        raise RuntimeError(f"Alembic export needs Blender's Python module bpy: {HOW}")
    if not found.is_file():
        raise RuntimeError(f"{ENV}={found} is not a file: {HOW}")
    return found
