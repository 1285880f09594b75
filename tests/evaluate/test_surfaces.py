"""The moved scan's surface measures (``physanim.evaluate.surfaces``) against analytic answers,
and the thin-part opening of the scan (``physanim.mesh.opening``)."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.evaluate.surfaces import (
    MIN_QUALITY,
    RestTriangles,
    iou,
    seam_faces,
    silhouettes,
    surface_quality,
    triangle_quality,
    view_cameras,
)
from physanim.mesh.opening import drop_thin_parts
from physanim.mesh.topology import triangle_areas


def grid_mesh(inside, extent_mm: tuple[float, float], step_mm: float = 0.5):
    """Vertices (N, 3) m and faces of the grid cells of [0, w] x [0, h] mm whose centre
    ``inside(x, y)`` (mm) accepts, two triangles per cell, in the plane z = 0."""
    nx, ny = int(round(extent_mm[0] / step_mm)), int(round(extent_mm[1] / step_mm))
    xs, ys = np.meshgrid(np.arange(nx + 1) * step_mm, np.arange(ny + 1) * step_mm, indexing="ij")
    vertices = 1e-3 * np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    keep = inside((i + 0.5) * step_mm, (j + 0.5) * step_mm).ravel()
    v00 = (i * (ny + 1) + j).ravel()[keep]
    v10, v01 = v00 + ny + 1, v00 + 1
    v11 = v10 + 1
    faces = np.r_[np.c_[v00, v10, v11], np.c_[v00, v11, v01]]
    used, inverse = np.unique(faces, return_inverse=True)
    return vertices[used], inverse.reshape(faces.shape)


def test_stretch_is_the_largest_singular_value_and_sees_a_turned_triangle() -> None:
    """A uniform stretch of 3 along x reads 3 on every triangle, a rigid rotation 1; random
    deformations agree with the SVD of the deformation gradient; a triangle mirrored through
    its plane is turned over, no other."""
    rng = np.random.default_rng(0)
    rest, faces = grid_mesh(lambda x, y: np.ones_like(x, bool), (10.0, 10.0), 1.0)
    tri = RestTriangles.of(rest, faces)
    stretched, turned = tri.stretch(rest * [3.0, 1.0, 1.0])
    np.testing.assert_allclose(stretched, 3.0, rtol=1e-12)
    assert not turned.any()
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    np.testing.assert_allclose(tri.stretch(rest @ q.T + 0.1)[0], 1.0, rtol=1e-10)
    moved = rest + 1e-3 * rng.normal(size=rest.shape)
    r, p = rest[faces], moved[faces]
    e1, e2 = r[:, 1] - r[:, 0], r[:, 2] - r[:, 0]  # rest triangles lie in z = 0
    dm = np.stack([e1[:, :2], e2[:, :2]], axis=-1)
    ds = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], axis=-1)
    svd = np.linalg.svd(ds @ np.linalg.inv(dm), compute_uv=False)[:, 0]
    np.testing.assert_allclose(tri.stretch(moved)[0], svd, rtol=1e-10)
    flipped = rest.copy()
    f0 = faces[7]
    flipped[f0[0]] = flipped[f0[1]] + flipped[f0[2]] - rest[f0[0]]  # across its far edge
    assert tri.stretch(flipped)[1][7]


def test_silhouette_overlap_of_a_shifted_plate() -> None:
    """A 40 mm square plate shifted 4 mm sideways against itself: the two outlines overlap by
    (40 - 4) / (40 + 4) (same depth, so the same image scale), to the pixel."""
    plate, faces = grid_mesh(lambda x, y: np.ones_like(x, bool), (40.0, 40.0), 2.0)
    size = (200, 240)
    shifted = plate + [0.004, 0.0, 0.0]
    cameras = view_cameras(np.r_[plate, shifted], size, (0.0,))  # both in view
    masks = silhouettes(np.stack([plate, shifted]), faces, cameras, size)
    assert masks.shape == (2, 1, 240, 200)
    assert iou(masks[0], masks[0])[0] == 1.0
    assert iou(masks[0], masks[1])[0] == pytest.approx(36.0 / 44.0, abs=0.01)


def test_silhouettes_compare_outlines_so_an_opened_mouth_is_no_loss() -> None:
    """A plate with a 10 x 4 mm slot (a mouth the lip seam let open) against the same plate
    shut: the outlines agree exactly; the slot moved to the border (a gap in the outline)
    is a loss of its area, 40 of 1600 mm^2."""
    size = (200, 240)
    whole, faces = grid_mesh(lambda x, y: np.ones_like(x, bool), (40.0, 40.0), 1.0)

    def slot(x0: float):
        return lambda x, y: ~((np.abs(x - x0) < 5.0) & (np.abs(y - 20.0) < 2.0))

    cameras = view_cameras(whole, size, (0.0,))
    masks = silhouettes(whole[None], faces, cameras, size)
    for x0, expected in ((20.0, 1.0), (5.0, 1560.0 / 1600.0)):
        holed, holed_faces = grid_mesh(slot(x0), (40.0, 40.0), 1.0)
        opened = silhouettes(holed[None], holed_faces, cameras, size)
        assert iou(opened[0], masks[0])[0] == pytest.approx(expected, abs=0.003)


def test_surface_quality_sees_a_flap_the_truth_does_not_have() -> None:
    """A plate whose corner region folds forward (a flap) in the model but not in the truth:
    the side view's overlap falls, a triangle across the fold stretches, and the folded ones
    turn over; the truth against itself is perfect."""
    plate, faces = grid_mesh(lambda x, y: np.ones_like(x, bool), (40.0, 40.0), 2.0)
    size = (160, 200)
    cameras = view_cameras(plate, size, (0.0, 70.0))
    truth = np.stack([plate, plate])
    flap = plate.copy()
    corner = (plate[:, 0] > 0.03) & (plate[:, 1] > 0.03)
    flap[corner, 2] += 0.02  # 20 mm towards the camera: a flap sticking out
    flap[corner, 0] = 0.06 - flap[corner, 0]  # and folded back over the plate
    model = np.stack([plate, flap])
    truth_masks = silhouettes(truth, faces, cameras, size)
    away = np.ones(len(faces), bool)
    same = surface_quality(truth, truth_masks, faces, away, cameras, size)
    np.testing.assert_array_equal(same.silhouette_iou, 1.0)
    np.testing.assert_allclose(same.max_stretch, 1.0)
    bad = surface_quality(model, truth_masks, faces, away, cameras, size)
    assert bad.silhouette_iou[1, 1] < 0.95
    assert bad.max_stretch[1] > 3.0
    assert bad.inverted[1] > 0 and bad.inverted[0] == 0


def test_seam_faces_are_those_touching_a_duplicated_vertex() -> None:
    """Vertices 1 and 4 copy the same uncut vertex: the faces using either are the seam's."""
    faces = np.array([[0, 1, 2], [2, 3, 0], [4, 5, 6], [5, 6, 7]])
    parent = np.array([0, 1, 2, 3, 1, 5, 6, 7])
    np.testing.assert_array_equal(seam_faces(faces, parent), [True, False, True, False])


def test_thin_strip_dropped_and_the_plate_and_a_wide_strip_kept() -> None:
    """A 40 mm plate with a 2 mm strip and an 8 mm strip reaching out of it: opening at 5 mm
    drops the thin strip whole and keeps the plate (less its rounded corners) and the wide
    strip; a width of 0 keeps everything."""

    def inside(x, y):
        plate = x < 40.0
        thin = (x >= 40.0) & (np.abs(y - 10.0) < 1.0)
        wide = (x >= 40.0) & (np.abs(y - 30.0) < 4.0)
        return plate | thin | wide

    vertices, faces = grid_mesh(inside, (60.0, 40.0), 0.5)
    kept = drop_thin_parts(vertices, faces, 0.005)
    centre = 1e3 * vertices[kept].mean(axis=1)
    area = triangle_areas(vertices, kept)
    assert not ((centre[:, 0] > 41.0) & (np.abs(centre[:, 1] - 10.0) < 2.0)).any()
    wide = (centre[:, 0] > 40.0) & (np.abs(centre[:, 1] - 30.0) < 5.0)
    assert area[wide].sum() >= 0.85 * 20e-3 * 8e-3  # less its two rounded corners
    assert area[centre[:, 0] < 40.0].sum() >= 0.99 * 40e-3 * 40e-3
    np.testing.assert_array_equal(drop_thin_parts(vertices, faces, 0.0), faces)
    with pytest.raises(ValueError, match="min_width_m"):
        drop_thin_parts(vertices, faces, 0.09)


def test_slivers_are_left_out_of_the_stretch() -> None:
    """Triangle quality: 1 for an equilateral triangle, half-square 0.866, a 1 % high sliver
    0.0231 (below MIN_QUALITY); moving the sliver's apex 0.2 of its base out of line would
    read a stretch of 20: surface_quality does not count it."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0, 1, 0], [0.5, 0.01, 0]])
    faces = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]])
    np.testing.assert_allclose(triangle_quality(v, faces), [1.0, 0.866, 0.0231], atol=1e-3)
    assert triangle_quality(v, faces)[2] < MIN_QUALITY
    moved = v.copy()
    moved[4, 2] = 0.2
    assert RestTriangles.of(v, faces[2:]).stretch(moved)[0][0] > 19.0
    cameras = view_cameras(v, (64, 64), (0.0,))
    frames = np.stack([v, moved])
    masks = silhouettes(frames, faces, cameras, (64, 64))
    q = surface_quality(frames, masks, faces, np.ones(3, bool), cameras, (64, 64))
    np.testing.assert_allclose(q.max_stretch, 1.0)


def test_the_capture_side_of_the_truth_is_made_once_and_read_back(tmp_path, monkeypatch) -> None:
    """``capture_against_truth``: on a disc of scan that lies on a truth sheet sliding 2 mm
    up, each scan vertex's true motion is the slide, the captured scan that moves with it
    keeps the truth's silhouettes (IoU 1); a second call (a material edit: the same capture
    and truth) reads the cache without following the truth again, to the bit; another capture
    is made anew."""
    from types import SimpleNamespace

    import physanim.evaluate.fidelity as fidelity
    from physanim.evaluate.face import EvaluateParams, capture_against_truth
    from physanim.evaluate.truth import Truth
    from physanim.store.file_cache import FileCache

    disc = lambda x, y: (x - 10) ** 2 + (y - 10) ** 2 < 64  # noqa: E731
    scan_v, scan_f = grid_mesh(disc, (20.0, 20.0))
    sheet_v, sheet_f = grid_mesh(lambda x, y: x == x, (20.0, 20.0), step_mm=1.0)
    slide = np.array([0.0, 0.002, 0.0]) * np.arange(3)[:, None, None]  # (3, 1, 3) m
    truth = Truth(sheet_v[None] + slide, sheet_f, None, [])
    run = SimpleNamespace(
        scan_vertices=scan_v, scan_faces=scan_f, scan_parent=np.arange(len(scan_v)),
        kinematic=scan_v[None] + slide,
    )  # fmt: skip
    params, cache = EvaluateParams(), FileCache(tmp_path / "cache")
    made = capture_against_truth(run, truth, params, cache)
    np.testing.assert_allclose(made.scan_truth, np.broadcast_to(slide, (3, len(scan_v), 3)),
                               atol=1e-9)  # fmt: skip
    assert np.all(made.kinematic.silhouette_iou == 1.0) and made.truth_masks.any()

    def never(*args, **kwargs):
        raise AssertionError("the truth was followed again")

    monkeypatch.setattr(fidelity, "follow_truth", never)
    again = capture_against_truth(run, truth, params, cache)
    for a, b in ((made.scan_truth, again.scan_truth), (made.truth_masks, again.truth_masks),
                 (made.kinematic.max_stretch, again.kinematic.max_stretch)):  # fmt: skip
        np.testing.assert_array_equal(a, b)
    other = SimpleNamespace(**{**vars(run), "kinematic": run.kinematic * 1.01})
    with pytest.raises(AssertionError, match="followed again"):
        capture_against_truth(other, truth, params, cache)
