"""The files opened in Blender (``bpy``, optional: ``pip install '.[blender]'``): stepped
frame by frame, the vertices must be where the animation puts them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from physanim.export import missing
from physanim.export.alembic import write_alembic
from physanim.export.animation import MeshAnimation
from physanim.export.gltf import morph_animation, rms_distance, write_glb
from physanim.export.usd import write_usd

pytestmark = pytest.mark.skipif(
    bool(missing("bpy")), reason="Blender's Python module bpy: pip install '.[blender]'"
)
PROBE = Path(__file__).with_name("blender_probe.py")


def in_blender(path: Path, anim: MeshAnimation) -> np.ndarray:
    """(T, N, 3) m Y-up: the vertices of ``path`` as Blender plays it at ``anim``'s rate."""
    out = path.with_suffix(".npy")
    cmd = [sys.executable, str(PROBE), str(path), repr(anim.fps), str(anim.frames), str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    return np.load(out)


def test_blender_plays_the_usd(tmp_path: Path, modes: MeshAnimation) -> None:
    usd = write_usd(modes, tmp_path / "fem.usdc")
    np.testing.assert_allclose(in_blender(usd, modes), modes.points, rtol=0, atol=1e-6)


def test_the_alembic_holds_every_frame_at_the_frame_rate(
    tmp_path: Path, modes: MeshAnimation
) -> None:
    # 30 fps, not Blender's default 24: samples written at the wrong rate would land between
    # the frames Blender steps here
    usd = write_usd(modes, tmp_path / "fem.usdc")
    abc = write_alembic(usd, tmp_path / "fem.abc", modes.fps, modes.frames)
    np.testing.assert_allclose(in_blender(abc, modes), modes.points, rtol=0, atol=1e-6)


def test_blender_plays_the_gltf_morph_animation(tmp_path: Path, modes: MeshAnimation) -> None:
    morph = morph_animation(modes, 1e-6, 16)
    played = in_blender(write_glb(morph, modes.faces, tmp_path / "fem.glb", "fem"), modes)
    np.testing.assert_allclose(played, morph.positions(), rtol=0, atol=1e-7)
    assert rms_distance(played, modes.points) <= 1e-6


def test_a_failed_conversion_says_why(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match="Alembic export of .*missing.usdc failed"):
        write_alembic(tmp_path / "missing.usdc", tmp_path / "x.abc", 30.0, 4)
