"""MeshAnimation: its checks and its per-frame normals against the mesh package's; the
message when a writer is not installed."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from physanim.export import require
from physanim.export.animation import MeshAnimation
from physanim.mesh.topology import vertex_normals
from tests.commands import ROOT
from tests.export.conftest import sheet


def test_normals_are_those_of_vertex_normals_in_every_frame(modes: MeshAnimation) -> None:
    expected = np.stack([vertex_normals(p, modes.faces) for p in modes.points])
    assert modes.normals.shape == modes.points.shape and modes.normals.dtype == np.float32
    np.testing.assert_allclose(modes.normals, expected, atol=1e-6)
    assert modes.normals[:, :, 2].mean() > 0.9  # the sheet faces +z (counter-clockwise)


def test_a_vertex_without_triangles_has_a_zero_normal() -> None:
    vertices, faces = sheet(4)
    points = np.concatenate([vertices, [[1.0, 1.0, 1.0]]])[None]
    normals = MeshAnimation("lone", points, faces, 30.0).normals
    np.testing.assert_array_equal(normals[0, -1], 0.0)
    np.testing.assert_allclose(np.linalg.norm(normals[0, :-1], axis=1), 1.0, atol=1e-6)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (dict(name="2nd"), "identifier"),
        (dict(points=np.zeros((4, 3))), "points must be"),
        (dict(points=np.full((2, 16, 3), np.nan)), "finite"),
        (dict(faces=np.array([[0, 1, 16]])), "faces must be"),
        (dict(fps=0.0), "fps must be positive"),
    ],
)
def test_malformed_animations_are_refused(change: dict, message: str) -> None:
    vertices, faces = sheet(4)
    args = dict(name="ok", points=np.stack([vertices] * 2), faces=faces, fps=30.0) | change
    with pytest.raises(ValueError, match=message):
        MeshAnimation(**args)


def test_a_missing_writer_names_the_extra_to_install() -> None:
    """In an interpreter without the site packages (none of the writers), the export says
    which extras of pyproject.toml bring them."""
    code = (
        "import sys; sys.path = [p for p in sys.path if 'site-packages' not in p]; "
        f"sys.path.insert(0, {str(ROOT)!r}); from physanim.export import require; "
        "require('pxr', 'pygltflib')"
    )
    done = subprocess.run([sys.executable, "-I", "-c", code], capture_output=True, text=True)
    assert done.returncode == 1
    assert "export needs pxr, pygltflib: pip install '.[export]'" in done.stderr
    require("pxr", "pygltflib")  # here they are


def test_a_missing_blender_says_how_to_get_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An Alembic export with PHYSANIM_BLENDER_PYTHON naming no file fails before Blender
    runs, naming the variable and the make target."""
    from physanim.export.alembic import write_alembic
    from physanim.export.blender import ENV

    monkeypatch.setenv(ENV, str(tmp_path / "no-python"))
    with pytest.raises(RuntimeError, match=f"{ENV}=.*no-python is not a file.*make setup-blender"):
        write_alembic(tmp_path / "x.usdc", tmp_path / "x.abc", 30.0, 4)
    assert not (tmp_path / "x.abc").exists()
