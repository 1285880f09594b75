"""The panel's side view (motion towards the camera) and the captured scan's error colouring,
on the real face000 scan."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import zarr
from matplotlib import colormaps

from physanim.cameras import frontal_camera
from physanim.evaluate.truth import Truth
from physanim.pipeline import DatasetParams
from physanim.render.colours import BACKGROUND, BAR_HEIGHT, NO_VALUE
from physanim.render.face_panel import (
    FIT_TITLE,
    KINEMATIC_TITLE,
    SIDE,
    TileParams,
    motion_tiles,
    scan_error_mm,
)
from physanim.store import write_array
from tasks import tiles as tiles_stage

SIZE = (240, 320)  # (W, H) px
BG = np.round(255 * np.asarray(BACKGROUND)).astype(np.uint8)
PUSH_M = 0.008  # how far the lower face moves towards the camera


def face_mask(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels that are not background."""
    return np.abs(image.astype(int) - BG).sum(axis=2) > 6


def leftmost(mask: np.ndarray) -> np.ndarray:
    """(H,) column of each row's first face pixel, -1 where the row is empty."""
    return np.where(mask.any(axis=1), mask.argmax(axis=1), -1)


def row_heights(vertices: np.ndarray, view_height: int) -> np.ndarray:
    """(view_height,) m: the actor's height y seen on each image row of the tiles' camera
    (framed on ``vertices`` (N, 3) m for a colour bar), at its focal point's depth."""
    camera = frontal_camera(vertices, SIZE, bar_px=BAR_HEIGHT)
    distance = np.linalg.norm(np.subtract(camera.position, camera.focal_point))
    focal_px = (view_height / 2) / np.tan(np.radians(camera.view_angle) / 2)
    above_centre_px = (view_height - 1) / 2 - np.arange(view_height)
    return camera.focal_point[1] + above_centre_px * distance / focal_px


def render(actor, captured: np.ndarray, params: TileParams, error_mm=None) -> dict:
    """``motion_tiles`` of the actor's scan moving as ``captured`` (R, N, 3) m (a one-triangle
    fit mesh beside it)."""
    fit = np.zeros((len(captured), 3, 3))
    fit[:, 1, 0] = fit[:, 2, 1] = 0.05
    return motion_tiles(
        fit, np.array([[0, 1, 2]]), captured, actor.vertices, actor.faces, params,
        lambda name: None, error_mm,
    )  # fmt: skip


def test_side_view_shows_the_lower_face_moving_towards_the_camera(actor):
    """A pucker-like push: the face below the nose moves 8 mm out of the face (+z, towards the
    frontal camera). The 70 deg side view's profile moves by the push's projection, 8 mm *
    sin(70 deg) (19 px), and the forehead stays put; the frontal outline hardly changes."""
    v = actor.vertices
    ramp = np.clip(-v[:, 1] / 0.015, 0.0, 1.0)  # 0 above y = 0, full push below y = -15 mm
    pushed = v + PUSH_M * ramp[:, None] * np.array([0.0, 0.0, 1.0])
    params = TileParams(tile_width_px=SIZE[0], tile_height_px=SIZE[1], side_view_deg=70.0)
    tiles = render(actor, np.stack([v, pushed]), params)
    assert list(tiles) == [FIT_TITLE, KINEMATIC_TITLE, KINEMATIC_TITLE + SIDE]
    front, side = tiles[KINEMATIC_TITLE], tiles[KINEMATIC_TITLE + SIDE]
    assert front.shape == side.shape == (2, SIZE[1], SIZE[0], 3)

    # the projection's scale: the tile has no colour bar, the camera is framed for one
    camera = frontal_camera(v, SIZE, bar_px=BAR_HEIGHT)
    distance = np.linalg.norm(np.subtract(camera.position, camera.focal_point))
    focal_px = (SIZE[1] / 2) / np.tan(np.radians(camera.view_angle) / 2)
    expected_px = PUSH_M * np.sin(np.radians(70.0)) * focal_px / distance

    def shift(tile: np.ndarray) -> np.ndarray:
        before, after = leftmost(face_mask(tile[0])), leftmost(face_mask(tile[1]))
        return np.where((before >= 0) & (after >= 0), before - after, 0)

    y = row_heights(v, SIZE[1])
    chin, brow = (y < -0.025) & (y > -0.035), (y > 0.03) & (y < 0.05)
    side_shift = shift(side)
    assert 0.75 * expected_px < np.median(side_shift[chin]) < 1.25 * expected_px
    assert np.abs(side_shift[brow]).max() <= 1
    # seen from the front it hardly shows: the face only grows by perspective (8 mm nearer
    # of 0.36 m), its outline moves about 3 px
    assert np.abs(shift(front)[chin]).mean() < 0.25 * np.median(side_shift[chin])


def test_no_side_view_when_turned_off(actor):
    params = TileParams(tile_width_px=120, tile_height_px=160, side_view_deg=0.0)
    tiles = render(actor, actor.vertices[None], params)
    assert list(tiles) == [FIT_TITLE, KINEMATIC_TITLE]


def moving_truth(actor) -> tuple[Truth, np.ndarray]:
    """A truth whose lower face drops 4 mm at the second frame, and that displacement (2, N, 3)
    m of the actor's vertices."""
    disp = np.zeros((2, *actor.vertices.shape))
    disp[1, :, 1] = -0.004 * (actor.vertices[:, 1] < 0)
    return Truth(actor.vertices + disp, actor.faces, None, []), disp


def test_scan_error_is_the_distance_to_the_true_displacement(actor):
    truth, disp = moving_truth(actor)
    perfect = scan_error_mm(actor.vertices, actor.vertices + disp, truth)
    assert perfect.shape == (2, len(actor.vertices)) and perfect.max() < 1e-6
    frozen = scan_error_mm(actor.vertices, np.stack([actor.vertices] * 2), truth)
    np.testing.assert_allclose(frozen, 1e3 * np.linalg.norm(disp, axis=-1), atol=1e-6)


def test_error_colouring_is_the_bottom_colour_for_a_perfect_capture(actor):
    """A perfect capture's scan tiles are shaded in the error map's bottom colour (a grey of
    BuPu's near-white) with the error's colour bar; a 4 mm error on the lower face (the top of
    the bar) shows purple there and only there, in both views."""
    truth, disp = moving_truth(actor)
    params = TileParams(tile_width_px=SIZE[0], tile_height_px=SIZE[1], error_max_mm=4.0)
    captured = actor.vertices + disp
    perfect = scan_error_mm(actor.vertices, captured, truth)
    frozen = scan_error_mm(actor.vertices, np.stack([actor.vertices] * 2), truth)
    tiles = render(actor, captured, params, np.stack([perfect[1], frozen[1]]))
    bottom, top = (np.asarray(colormaps["BuPu"](x)[:3]) for x in (0.0, 1.0))
    y = row_heights(actor.vertices, SIZE[1] - BAR_HEIGHT)
    for title in (KINEMATIC_TITLE, KINEMATIC_TITLE + SIDE):
        view, bar = tiles[title][:, :-BAR_HEIGHT], tiles[title][0, -BAR_HEIGHT:].astype(float)
        for end in (bottom, top):  # the bar shows both ends of the map
            assert np.abs(bar.reshape(-1, 3) - np.round(255 * end)).sum(axis=1).min() < 20
        ok = view[0][face_mask(view[0])].astype(float)
        # shaded bottom colour: every pixel a grey of (247, 252, 253), no purple
        assert np.abs(ok / ok.sum(axis=1, keepdims=True) - bottom / bottom.sum()).max() < 0.02
        wrong = view[1].astype(float)
        share = wrong / np.maximum(wrong.sum(axis=-1, keepdims=True), 1.0)
        purple = face_mask(view[1]) & (share[..., 1] < 0.2) & (share[..., 2] > 0.3)
        lower, upper = (y < -0.01) & (y > -0.03), y > 0.01
        assert purple[lower].sum() > 0.6 * face_mask(view[1])[lower].sum()
        assert not purple[upper].any()
    assert top[2] - top[1] > 0.2 and top[0] - top[1] > 0.1  # the map's top is purple


def test_tiles_key_reads_the_truth_only_for_the_error_colouring(tmp_path: Path):
    """Plain skin: the tiles' key ignores the truth; 'auto': a truth added or edited renders
    the tiles again; 'error' without a truth fails before rendering, naming the path."""
    dataset = DatasetParams(dir=str(tmp_path))

    def fingerprint(colour: str) -> object:
        return tiles_stage.fingerprint(dataset, TileParams(scan_colour=colour))

    assert fingerprint("skin") == {} and fingerprint("auto") == {"truth": "none"}
    truth = zarr.open_group(tmp_path / "ground_truth.zarr", mode="w")
    write_array(truth, "faces", np.zeros((4, 3), np.int64))
    assert fingerprint("skin") == {} and fingerprint("auto") != {"truth": "none"}
    assert fingerprint("auto") == fingerprint("error")

    ctx = SimpleNamespace(dataset_dir=tmp_path / "elsewhere", progress=lambda name: None)
    with pytest.raises(ValueError, match="no truth .*elsewhere/ground_truth.zarr"):
        tiles_stage.compute(TileParams(scan_colour="error"), None, None, None, None, ctx)


def test_error_colour_bar_spans_the_moving_skins_error() -> None:
    """20 frames of 1000 vertices at rest with no error but for one frame where a tenth of
    them (a chin at the jaw drop) err 5 mm, and one wild edge vertex at 100 mm: the bar's top
    is 5 mm (all errors' 99th percentile would read 0: the chin all in the top colour); a set
    ``error_max_mm`` wins."""
    error = np.zeros((20, 1000))
    error[7, :100] = 5.0
    error[3, 999] = 100.0
    assert TileParams().error_colours(error).clim == (0.0, 5.0)
    assert TileParams(error_max_mm=2.0).error_colours(error).clim == (0.0, 2.0)


def test_a_vertex_without_truth_is_grey_not_a_small_error() -> None:
    """NaN errors (scan vertices with no true surface under them) neither set the bar's top
    nor take a colour of the map: they are drawn in NO_VALUE's grey."""
    error = np.zeros((20, 1000))
    error[7, :100] = 5.0
    error[:, 900:] = np.nan
    colour_map = TileParams().error_colours(error)
    assert colour_map.clim == (0.0, 5.0)
    rgb = colour_map.colours(np.array([0.0, 5.0, np.nan]))
    np.testing.assert_array_equal(rgb[2], np.round(255 * np.asarray(NO_VALUE)))
    assert not (rgb[:2] == rgb[2]).all(axis=1).any()
