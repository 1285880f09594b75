"""Integrity of the packaged CANDIDE-style face model."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.face.landmarks import FEATURE_POINTS, mirror_name
from physanim.face.model import load_face_model, pose_matrix

REQUIRED_AUS = (
    "jaw_drop", "lips_part", "lip_corner_puller_L", "lip_corner_puller_R", "lip_stretcher_L",
    "lip_stretcher_R", "lip_corner_depressor_L", "lip_corner_depressor_R", "upper_lip_raiser",
    "inner_brow_raiser_L", "inner_brow_raiser_R", "outer_brow_raiser_L", "outer_brow_raiser_R",
    "brow_lowerer", "eye_closure_L", "eye_closure_R",
)  # fmt: skip


@pytest.fixture(scope="module")
def model():
    return load_face_model()


def _signed_areas_xy(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    a, b, c = (vertices[triangles[:, k], :2] for k in range(3))
    ab, ac = b - a, c - a
    return 0.5 * (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])


def test_sizes_and_names(model):
    assert 100 <= model.n_vertices <= 150
    assert 150 <= len(model.triangles) <= 250
    assert set(FEATURE_POINTS) <= set(model.vertex_names)
    assert len(set(model.vertex_names)) == model.n_vertices
    assert set(REQUIRED_AUS) <= set(model.au_names)
    assert {"face_width", "face_height", "nose_protrusion", "mouth_width", "eye_separation"} <= set(
        model.su_names
    )
    assert model.su.shape == (len(model.su_names), model.n_vertices, 3)
    assert model.au.shape == (len(model.au_names), model.n_vertices, 3)


def test_geometry_is_a_face(model):
    v = {n: model.vertices[model.names[n]] for n in FEATURE_POINTS}
    np.testing.assert_allclose(v["pronasale"], 0.0, atol=1e-12)  # actor-frame origin
    assert v["glabella"][1] > v["ex_L"][1] > v["pronasale"][1] > v["ch_L"][1]
    assert v["ex_L"][0] > 0 > v["ex_R"][0]  # +x is the actor's left
    assert v["pronasale"][2] >= model.vertices[:, 2].max() - 1e-3  # nose tip is frontmost
    width = v["ex_L"][0] - v["ex_R"][0]
    assert 0.04 < width < 0.12  # metres


def test_triangles_valid_and_manifold(model):
    tri = model.triangles
    assert tri.min() >= 0 and tri.max() < model.n_vertices
    assert (np.diff(np.sort(tri, axis=1), axis=1) > 0).all()  # no repeated vertex
    assert len(np.unique(np.sort(tri, axis=1), axis=0)) == len(tri)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert counts.max() <= 2  # every edge borders one or two triangles
    assert (_signed_areas_xy(model.vertices, tri) > 0).all()  # consistently oriented to +z
    assert np.isin(np.arange(model.n_vertices), tri).all()  # no isolated vertex


def test_mouth_and_eyes_are_open_boundaries(model):
    """Lips can part: no triangle joins an upper inner-lip vertex to a lower one."""
    upper = model.index(["stomion_superius", "lip_upper_in_1_L", "lip_upper_in_2_R"])
    lower = model.index(["stomion_inferius", "lip_lower_in_1_L", "lip_lower_in_2_R"])
    tri = model.triangles
    assert not (np.isin(tri, upper).any(axis=1) & np.isin(tri, lower).any(axis=1)).any()


def test_mirror_is_an_involution_and_layout_symmetric(model):
    m = model.mirror
    np.testing.assert_array_equal(m[m], np.arange(model.n_vertices))
    for i, n in enumerate(model.vertex_names):
        assert model.vertex_names[m[i]] == mirror_name(n)
    np.testing.assert_allclose(model.layout[m] * [-1, 1], model.layout, atol=1e-12)


def test_symmetric_action_unit_pairs_mirror_each_other(model):
    flip = np.array([-1.0, 1.0, 1.0])
    for name in model.au_names:
        if name.endswith("_L"):
            left = model.au[model.au_names.index(name)]
            right = model.au[model.au_names.index(mirror_name(name))]
            np.testing.assert_allclose(right[model.mirror] * flip, left, atol=1e-12)
            mag = np.linalg.norm(left, axis=1)
            assert mag @ model.layout[:, 0] > 0, name  # an _L unit acts on the actor's left


@pytest.mark.parametrize("kind", ["au", "su"])
def test_units_are_smooth_and_fold_free(model, kind):
    """Each unit moves the face by millimetres, without spikes and without flipping triangles."""
    fields, names = (model.au, model.au_names) if kind == "au" else (model.su, model.su_names)
    for name, field in zip(names, fields, strict=True):
        peak = np.linalg.norm(field, axis=1).max()
        assert 1e-3 < peak < 0.02, name  # 1-20 mm at one unit
        deformed = model.vertices + field
        assert (_signed_areas_xy(deformed, model.triangles) > 0).all(), name
        # no isolated spike: every moving vertex has a neighbour moving at least 1/4 as much
        tri = model.triangles
        mag = np.linalg.norm(field, axis=1)
        neighbour_max = np.zeros(model.n_vertices)
        for a, b in ((0, 1), (1, 2), (2, 0), (1, 0), (2, 1), (0, 2)):
            np.maximum.at(neighbour_max, tri[:, a], mag[tri[:, b]])
        moving = mag > 0.1 * peak
        assert (neighbour_max[moving] >= 0.25 * mag[moving]).all(), name


def test_shape_applies_units_and_pose(model):
    rng = np.random.default_rng(1)
    su, au = rng.uniform(-1, 1, len(model.su)), rng.uniform(0, 1, len(model.au))
    pose = np.array([0.1, -0.2, 0.05, 0.01, 0.02, 0.5])
    rot, t = pose_matrix(pose)
    expected = (model.vertices + np.einsum("i,ivc->vc", su, model.su)) + np.einsum(
        "j,jvc->vc", au, model.au
    )
    np.testing.assert_allclose(model.shape(su, au, pose), expected @ rot.T + t, atol=1e-12)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    with pytest.raises(ValueError, match="au"):
        model.shape(au=np.zeros(3))


def test_jaw_drop_opens_the_mouth_downwards(model):
    jaw = model.au[model.au_names.index("jaw_drop")]
    assert jaw[model.names["pogonion"], 1] < -0.005  # chin down > 5 mm
    assert np.abs(jaw[model.names["glabella"]]).max() == 0.0
    gap = jaw[model.names["stomion_inferius"], 1] - jaw[model.names["stomion_superius"], 1]
    assert gap < -0.003
