"""Offscreen face renders: real face000 scan, both backends, colour bars, turntable."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib import colormaps
from scipy.ndimage import binary_erosion

from physanim.cameras import frontal_camera, turntable
from physanim.render.colours import BACKGROUND, BAR_HEIGHT, ColourMap
from physanim.render.face import render_sequence, render_views
from physanim.render.raster_backend import LIGHT_COLOURS, LIGHT_DIRECTIONS
from physanim.render.surface import render_surface

SIZE = (240, 320)  # (W, H) px
BG = np.round(255 * np.asarray(BACKGROUND)).astype(np.uint8)


def face_mask(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels that are not background."""
    return np.abs(image.astype(int) - BG).sum(axis=2) > 6


@pytest.mark.parametrize("backend", ["vtk", "raster"])
def test_skin_render_is_lit_and_framed(actor, backend):
    img = render_surface(actor.vertices, actor.faces, size=SIZE, backend=backend)
    assert img.shape == (SIZE[1], SIZE[0], 3) and img.dtype == np.uint8
    mask = face_mask(img)
    # The scan spans most of the frame but is not clipped: the border is background.
    assert 0.3 < mask.mean() < 0.85
    assert not mask[0].any() and not mask[-1].any()
    assert not mask[:, 0].any() and not mask[:, -1].any()
    # Lit: not black, and shading varies over the face (not a single colour).
    lum = img[mask].mean(axis=1)
    assert lum.mean() > 90
    assert lum.std() > 10
    # The bounding box of the face fills the width or the height of the view (fit to bbox).
    rows, cols = np.nonzero(mask)
    assert max(np.ptp(rows) / SIZE[1], np.ptp(cols) / SIZE[0]) > 0.8


@pytest.mark.parametrize("coloured", [False, True])
def test_backends_agree_pixel_for_pixel(actor, coloured):
    """The project's rasteriser and shader draw what VTK (llvmpipe, its light kit) draws: the
    same outline and, inside it, the same colour to a grey level (the skin, and a colour map
    over the face)."""
    cam = frontal_camera(actor.vertices, SIZE)
    style = {}
    if coloured:
        style = dict(
            scalars=1e3 * actor.vertices[:, 1], colour_map=ColourMap("y (mm)", clim=(-90, 90))
        )
    a, b = (
        render_surface(actor.vertices, actor.faces, camera=cam, size=SIZE, backend=backend, **style)
        for backend in ("vtk", "raster")
    )
    a_in, b_in = face_mask(a), face_mask(b)
    assert (a_in & b_in).sum() / (a_in | b_in).sum() > 0.998
    inside = binary_erosion(a_in & b_in, iterations=2)  # off the outline's aliased pixels
    diff = np.abs(a.astype(int) - b)[inside]
    assert diff.mean() < 0.5 and np.percentile(diff, 99.9) <= 2


def test_raster_lights_are_vtks_light_kit():
    """The raster backend's lights are those pyvista gives a VTK renderer (camera lights:
    VTK's camera frame is OpenCV's with y and z negated)."""
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True)
    try:
        lights = list(plotter.renderer.GetLights())
        towards = np.array([np.subtract(lt.GetPosition(), lt.GetFocalPoint()) for lt in lights])
        colours = np.array([lt.GetIntensity() * np.array(lt.GetDiffuseColor()) for lt in lights])
    finally:
        plotter.close()
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    np.testing.assert_allclose(towards * [1, -1, -1], LIGHT_DIRECTIONS, atol=2e-4)
    np.testing.assert_allclose(colours, LIGHT_COLOURS, atol=2e-4)


def test_colour_bar_and_colour_map(actor):
    # 4 mm on the actor's left (x > 0), 0 on the right: left side must be the red end.
    scalars = np.where(actor.vertices[:, 0] > 0.0, 4.0, 0.0)
    cmap = ColourMap("displacement (mm)", clim=(0.0, 4.0))
    img = render_surface(actor.vertices, actor.faces, scalars=scalars, colour_map=cmap, size=SIZE)
    assert img.shape == (SIZE[1], SIZE[0], 3)
    view, bar = img[:-BAR_HEIGHT], img[-BAR_HEIGHT:]
    # The bar shows both ends of the map and dark label text.
    ends = np.round(255 * np.array([colormaps["YlOrRd"](x)[:3] for x in (0.0, 1.0)]))
    flat = bar.reshape(-1, 3).astype(float)
    for end in ends:
        assert np.abs(flat - end).sum(axis=1).min() < 20
    assert (flat.sum(axis=1) < 150).sum() > 20  # text and ticks
    # Actor's left appears on the image right (camera in front of the face).
    mask = face_mask(view)
    greenness = view[..., 1] / (view[..., 0] + 1.0)  # pale yellow ~0.9, dark red ~0
    half = SIZE[0] // 2
    right = np.median(greenness[:, half + 10 :][mask[:, half + 10 :]])
    left = np.median(greenness[:, : half - 10][mask[:, : half - 10]])
    assert right < 0.3 < 0.7 < left


def test_region_legend(actor):
    labels = (actor.vertices[:, 1] > 0).astype(int)
    cmap = ColourMap("region", categories=("lower", "upper"))
    img = render_surface(actor.vertices, actor.faces, scalars=labels, colour_map=cmap, size=SIZE)
    bar = img[-BAR_HEIGHT:].reshape(-1, 3).astype(float)
    for c in colormaps["tab10"].colors[:2]:
        assert np.abs(bar - np.round(255 * np.array(c))).sum(axis=1).min() < 10


def test_turntable_rotates_about_view_up():
    cam = frontal_camera(np.array([[-1.0, -1, -1], [1, 1, 1]]) * 0.05)
    dist = cam.position[2] - cam.focal_point[2]
    side = turntable(cam, 90.0)
    np.testing.assert_allclose(side.position, np.array(cam.focal_point) + [dist, 0, 0], atol=1e-12)
    np.testing.assert_allclose(turntable(cam, 360.0).position, cam.position, atol=1e-12)


def test_sequence_isolated_matches_in_process(actor):
    t = 3
    lift = np.linspace(0.0, 0.004, t)
    seq = actor.vertices[None] + lift[:, None, None] * np.array([0.0, 0.0, 1.0])
    scalars = np.repeat(1e3 * lift[:, None], len(actor.vertices), axis=1)
    cmap = ColourMap("displacement (mm)", clim=(0.0, 4.0))
    calls = []
    isolated = render_sequence(
        seq,
        actor.faces,
        scalars=scalars,
        colour_map=cmap,
        azimuth_deg=[0.0, 20.0, 40.0],
        size=SIZE,
        backend="vtk",
        progress=lambda done, total: calls.append((done, total)),
    )
    local = render_sequence(
        seq,
        actor.faces,
        scalars=scalars,
        colour_map=cmap,
        azimuth_deg=[0.0, 20.0, 40.0],
        size=SIZE,
        backend="vtk",
        isolate=False,
    )
    assert isolated.shape == (t, SIZE[1], SIZE[0], 3)
    assert calls[-1] == (t, t)
    assert np.abs(isolated.astype(int) - local).mean() < 1.0
    # Frames differ: the turntable moves and the colour goes from pale to red.
    assert np.abs(isolated[0].astype(int) - isolated[-1]).mean() > 5


def test_views_are_the_sequence_seen_turned(actor):
    """``render_views`` (each frame's normals and colours computed once for both cameras, the
    frames shared out over two threads) gives, per view, the frames ``render_sequence``
    renders turned by that azimuth, in frame order."""
    lift = np.array([0.0, 0.003, 0.006])
    seq = actor.vertices[None] + lift[:, None, None] * np.array([0.0, 0.0, 1.0])
    views = render_views(seq, actor.faces, (0.0, 90.0), size=SIZE, threads=2)
    assert views.shape == (2, 3, SIZE[1], SIZE[0], 3)
    for got, azimuth in zip(views, (0.0, 90.0), strict=True):
        alone = render_sequence(seq, actor.faces, azimuth_deg=[azimuth] * 3, size=SIZE)
        np.testing.assert_array_equal(got, alone)
    assert np.abs(views[0, 1].astype(int) - views[1, 1]).mean() > 5  # front and profile differ
    assert np.abs(views[1, 0].astype(int) - views[1, 2]).mean() > 0.5  # the lift shows


def test_bad_inputs_are_named(actor):
    with pytest.raises(ValueError, match="scalars must be per vertex"):
        render_surface(actor.vertices, actor.faces, scalars=np.zeros(7), size=SIZE)
    with pytest.raises(ValueError, match=r"vertices must be \(T, N, 3\)"):
        render_sequence(actor.vertices, actor.faces)
    with pytest.raises(ValueError, match="azimuth_deg"):
        render_sequence(actor.vertices[None], actor.faces, azimuth_deg=[0.0, 1.0])


def test_vtk_crash_is_reported_and_the_caller_survives(actor, monkeypatch):
    """A real VTK crash: with an unusable GL window class VTK segfaults at the first render.
    The isolated worker dies; the caller gets a RuntimeError saying so."""
    monkeypatch.setenv("VTK_DEFAULT_OPENGL_WINDOW", "vtkNoSuchRenderWindow")
    seq = actor.vertices[None].repeat(2, axis=0)
    with pytest.raises(RuntimeError, match="render worker exited"):
        render_sequence(seq, actor.faces, size=SIZE, backend="vtk")
