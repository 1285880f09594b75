"""The report's 3D viewer (``physanim.render.viewer``) opened in headless Chromium: it loads the
exported glTF files, shows the frame asked for, and the motion shows on screen.

Chromium and three.js are Debian packages (``make setup-test-system``, ``make setup-system``;
``.ci/run`` installs both); without them the browser test is skipped, saying which is missing.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from physanim.export.animation import MeshAnimation
from physanim.export.gltf import morph_animation, write_glb
from physanim.render.viewer import THREE_MISSING, three_available, write_viewer
from tests.export.conftest import sheet

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: The viewer page's background, sRGB 0-255 (#20242a).
BACKGROUND = np.array([0x20, 0x24, 0x2A])


def chromium(url: str, *args: str) -> str:
    """Run headless Chromium (software WebGL) on ``url``; its stdout."""
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", "--window-size=640,480",
           "--virtual-time-budget=15000", *args, url]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def covered(png: Path) -> tuple[float, float]:
    """The share of the picture (above the control bar) that is not background, and the mean
    image column of those pixels."""
    rgb = np.asarray(Image.open(png).convert("RGB"))[40:-60].astype(int)
    mesh = np.abs(rgb - BACKGROUND).sum(axis=-1) > 30
    return float(mesh.mean()), float(np.nonzero(mesh)[1].mean()) if mesh.any() else np.nan


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium (make setup-test-system)")
@pytest.mark.skipif(not three_available(), reason=THREE_MISSING)
def test_viewer_plays_the_exported_animation(tmp_path: Path) -> None:
    """A sheet sliding 40 mm towards the actor's left over 10 frames, written by the export's
    glTF writer: the page reports both models and 10 frames, the sheet covers a good part of
    the view at the first and the last frame (not a blank page), and at the last it is seen
    to the right (the actor's left faces the viewer's right)."""
    vertices, faces = sheet()
    slide = np.linspace(0.0, 0.04, 10)[:, None, None] * [1.0, 0.0, 0.0]
    animation = MeshAnimation("fem", vertices + slide, faces, 30.0)
    glb = write_glb(morph_animation(animation, 1e-5, 4), faces, tmp_path / "fem.glb", "fem")
    page = write_viewer(tmp_path / "report", {"FEM": glb, "captured scan": glb})
    dom = chromium(page.as_uri() + "#frame=9", "--dump-dom")
    status = re.search(r"<div id=\"status\">([^<]*)", dom)
    assert status and status.group(1) == "ready: 2 models, 10 frames", dom[-2000:]
    assert "frame 9 (0.30 s)" in dom
    shots = {}
    for frame in (0, 9):  # the last frame: where a repeating animation would wrap to the first
        png = tmp_path / f"frame{frame}.png"
        chromium(f"{page.as_uri()}#frame={frame}", f"--screenshot={png}")
        shots[frame] = covered(png)
    print("covered share, mean column", shots)
    for share, _ in shots.values():
        assert share > 0.05
    assert shots[9][1] > shots[0][1] + 10


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium (make setup-test-system)")
@pytest.mark.skipif(not three_available(), reason=THREE_MISSING)
def test_viewer_colours_each_vertex_by_its_error_on_request(tmp_path: Path) -> None:
    """Error colours for the FEM's vertices (the image-left half purple, the rest white):
    with #error=1 the sheet's left half is purple (blue over green) and its right half
    light, without it both are skin (red over blue); colours of the wrong count are refused
    in the status, and the model is shown plain."""
    vertices, faces = sheet()
    animation = MeshAnimation("fem", np.stack([vertices, vertices]), faces, 30.0)
    glb = write_glb(morph_animation(animation, 1e-5, 4), faces, tmp_path / "fem.glb", "fem")
    rgb = np.where((vertices[:, 0] < np.median(vertices[:, 0]))[:, None], [110, 20, 130], 255)
    legend = "largest error vs truth: white 0 to purple 1.00 mm and above"
    page = write_viewer(tmp_path / "report", {"FEM": glb}, colours={"FEM": (rgb, legend)})
    dom = chromium(page.as_uri() + "#frame=0&error=1", "--dump-dom")
    assert "ready: 1 models, 2 frames, error colours" in dom and legend in dom, dom[-2000:]
    halves = {}
    for colouring in (True, False):
        png = tmp_path / f"error{colouring}.png"
        chromium(f"{page.as_uri()}#frame=0{'&error=1' if colouring else ''}", f"--screenshot={png}")
        img = np.asarray(Image.open(png).convert("RGB"))[40:-60].astype(int)
        mesh = np.abs(img - BACKGROUND).sum(axis=-1) > 30
        cols = np.nonzero(mesh.any(axis=0))[0]
        mid = (cols.min() + cols.max()) // 2
        halves[colouring] = [img[:, a:b][mesh[:, a:b]].mean(axis=0)
                             for a, b in ((cols.min(), mid), (mid, cols.max() + 1))]  # fmt: skip
    print("mean colour of the left and right halves", halves)
    (left, right), (plain_left, plain_right) = halves[True], halves[False]
    assert left[2] > left[1] + 30 and right.min() > left.min() + 40
    assert plain_left[0] > plain_left[2] + 20 and plain_right[0] > plain_right[2] + 20
    wrong = write_viewer(tmp_path / "wrong", {"FEM": glb}, colours={"FEM": (rgb[:-1], legend)})
    dom = chromium(wrong.as_uri() + "#frame=0&error=1", "--dump-dom")
    assert f"FEM: {len(rgb) - 1} colours for {len(rgb)} vertices, shown plain" in dom


def test_viewer_names_what_is_missing(tmp_path: Path) -> None:
    """No model file, or no three.js where it is looked for: FileNotFoundError naming it."""
    with pytest.raises(FileNotFoundError, match="nothing.glb"):
        write_viewer(tmp_path, {"FEM": tmp_path / "nothing.glb"})
    with pytest.raises(FileNotFoundError, match="libjs-three"):
        write_viewer(tmp_path, {"FEM": tmp_path / "x.glb"}, root=tmp_path)
