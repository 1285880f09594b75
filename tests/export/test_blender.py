"""The files opened in Blender (``bpy`` in its own interpreter, ``make setup-blender``; ``make
test`` makes it): stepped frame by frame, the vertices must be where the animation puts them."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from physanim.export.alembic import write_alembic
from physanim.export.animation import MeshAnimation
from physanim.export.blender import HOW, blender_python
from physanim.export.gltf import morph_animation, rms_distance, write_glb
from physanim.export.usd import write_usd

BLENDER = blender_python()
pytestmark = pytest.mark.skipif(BLENDER is None, reason=f"no Blender (bpy): {HOW}")
PROBE = Path(__file__).with_name("blender_probe.py")


def in_blender(path: Path, fps: float, frames: int, out: Path | None = None) -> np.ndarray:
    """(frames, N, 3) m Y-up: the vertices of ``path`` as Blender plays it at ``fps``
    frames/s (through the file ``out``, default beside ``path``)."""
    out = out or path.with_suffix(".npy")
    cmd = [str(BLENDER), str(PROBE), str(path), repr(fps), str(frames), str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    return np.load(out)


def test_blender_plays_the_usd(tmp_path: Path, modes: MeshAnimation) -> None:
    usd = write_usd(modes, tmp_path / "fem.usdc")
    played = in_blender(usd, modes.fps, modes.frames)
    np.testing.assert_allclose(played, modes.points, rtol=0, atol=1e-6)


def test_the_alembic_holds_every_frame_at_the_frame_rate(
    tmp_path: Path, modes: MeshAnimation
) -> None:
    # 30 fps, not Blender's default 24: samples written at the wrong rate would land between
    # the frames Blender steps here
    usd = write_usd(modes, tmp_path / "fem.usdc")
    abc = write_alembic(usd, tmp_path / "fem.abc", modes.fps, modes.frames)
    played = in_blender(abc, modes.fps, modes.frames)
    np.testing.assert_allclose(played, modes.points, rtol=0, atol=1e-6)


def test_blender_plays_the_gltf_morph_animation(tmp_path: Path, modes: MeshAnimation) -> None:
    morph = morph_animation(modes, 1e-6, 16)
    glb = write_glb(morph, modes.faces, tmp_path / "fem.glb", "fem")
    played = in_blender(glb, modes.fps, modes.frames)
    np.testing.assert_allclose(played, morph.positions(), rtol=0, atol=1e-7)
    assert rms_distance(played, modes.points) <= 1e-6


def test_a_failed_conversion_says_why(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match="Alembic export of .*missing.usdc failed"):
        write_alembic(tmp_path / "missing.usdc", tmp_path / "x.abc", 30.0, 4)


def test_blender_plays_the_stages_files_as_the_store_holds_them(
    face_demo: tuple[Path, str], tmp_path: Path
) -> None:
    """The export stage's USD of the coarse demo, and an Alembic Blender writes of it, played
    in Blender: every frame's vertices where the store puts the FEM skin and the captured
    scan (1e-6 m), one frame per capture frame at the capture's rate."""
    import json

    from tests.commands import physanim
    from tests.conftest import COARSE
    from tests.export.test_stage import stored_motion

    data, _ = face_demo
    _, expected, out = stored_motion(data)
    show = physanim("show", "export", "--dataset", str(data), "-c", COARSE)
    folder = Path(json.loads(show.stdout)["files"]["folder"])
    for name, points in expected.items():
        usd, frames = folder / f"{name}.usdc", len(points)
        played = in_blender(usd, out.fps, frames, tmp_path / f"{name}-usd.npy")
        np.testing.assert_allclose(played, points, rtol=0, atol=1e-6)
        abc = write_alembic(usd, tmp_path / f"{name}.abc", out.fps, frames)
        played = in_blender(abc, out.fps, frames)
        np.testing.assert_allclose(played, points, rtol=0, atol=1e-6)
