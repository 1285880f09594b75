"""Alembic (.abc) of an exported USD, written by Blender (optional).

No Python binding of the Alembic library is on PyPI ('alembic' there is SQLAlchemy's
migration tool) or in Debian; Blender's exporter is one a technical artist knows. Blender
runs in a child process of its own interpreter (``physanim.export.blender``) on the script
``blender_scene.py`` beside this module, which imports nothing of physanim. Blender imports
the USD (its Y-up turned to Blender's Z-up by a root rotation) and its Alembic exporter
writes Y-up again, in metres, one sample per frame at the animation's frame rate.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from physanim.export.blender import require_blender

#: The script Blender's interpreter runs (standalone: only bpy and the standard library).
SCRIPT = Path(__file__).with_name("blender_scene.py")


def write_alembic(usd: Path, path: Path, fps: float, frames: int, timeout_s: float = 600) -> Path:
    """Write the Alembic ``path`` of the USD file ``usd`` (frames 0 .. ``frames``-1 at ``fps``
    frames/s) through Blender in a child process and return ``path``. RuntimeError with
    Blender's last output when it fails or there is no interpreter with ``bpy``."""
    python = require_blender()
    cmd = [str(python), str(SCRIPT), str(usd), str(path), repr(float(fps)), str(frames)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    if done.returncode != 0 or not Path(path).is_file():
        tail = (done.stdout + done.stderr)[-2000:]
        raise RuntimeError(f"Blender's Alembic export of {usd} failed ({done.returncode}): {tail}")
    return Path(path)
