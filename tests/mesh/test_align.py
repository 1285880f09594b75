"""Alignment: Umeyama, the seed's per-axis scaling (eqs 5.1-5.4), non-rigid refinement."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physanim.face.landmarks import FEATURE_POINTS
from physanim.face.model import load_face_model
from physanim.mesh.align import (
    align_motion_mesh,
    measure_axis_scales,
    per_axis_scale,
)
from physanim.mesh.binding import bind_points
from physanim.mesh.params import AlignParams
from physanim.transforms import fit_transform


def test_similarity_recovers_a_known_similarity():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(10, 3))
    rot = Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix()
    dst = 1.7 * src @ rot.T + np.array([0.1, -0.2, 0.3])
    sim = fit_transform(src, dst)
    assert sim.scale == pytest.approx(1.7, rel=1e-12)
    np.testing.assert_allclose(sim.rotation, rot, atol=1e-12)
    np.testing.assert_allclose(sim.apply(src), dst, atol=1e-12)
    rigid = fit_transform(src, src @ rot.T, with_scale=False)
    assert rigid.scale == 1.0 and np.linalg.det(rigid.rotation) == pytest.approx(1.0)


def test_similarity_rejects_collinear_landmarks():
    line = np.outer(np.arange(4.0), [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="collinear"):
        fit_transform(line, line)


def test_per_axis_scaling_recovers_width_and_up_down_height_ratios():
    rng = np.random.default_rng(1)
    moving = rng.uniform(-0.05, 0.05, (12, 3))
    moving[0] = 0.0  # nose tip at the origin
    nose_tip = np.array([0.01, 0.02, 0.03])
    # Target: x and z scaled by 1.2, y by 0.9 above the nose tip and 1.3 below, then shifted.
    y = moving[:, 1]
    target = np.c_[1.2 * moving[:, 0], np.where(y > 0, 0.9, 1.3) * y, 1.2 * moving[:, 2]]
    target += nose_tip
    scales = measure_axis_scales(moving + 0.5, target, nose_index=0)
    assert (scales.x, scales.z, scales.y_up, scales.y_down) == pytest.approx((1.2, 1.2, 0.9, 1.3))
    moved = per_axis_scale(moving + nose_tip, scales)  # rigidly aligned: same nose tip
    np.testing.assert_allclose(moved, target, atol=1e-15)


def test_face_model_aligns_onto_face000_and_binds(skin, landmarks):
    v_scan, f_scan = skin
    model = load_face_model()
    # A different identity (random Shape Units), so the wireframe does not fit the scan already.
    neutral = model.deform(su=np.random.default_rng(0).uniform(-1, 1, len(model.su_names)))
    lm_idx = model.index(FEATURE_POINTS)
    targets = np.array([landmarks[n] for n in FEATURE_POINTS])
    nose = FEATURE_POINTS.index("pronasale")
    before = align_motion_mesh(
        neutral,
        model.triangles,
        lm_idx,
        v_scan,
        f_scan,
        targets,
        nose,
        AlignParams(refine_iterations=0),
    )
    after = align_motion_mesh(
        neutral, model.triangles, lm_idx, v_scan, f_scan, targets, nose, AlignParams()
    )
    # Landmarks are held on their scan positions; the rest of the wireframe moves onto the skin.
    assert np.abs(after.vertices[lm_idx] - targets).max() < 1e-3
    d_before = bind_points(before.vertices, v_scan, f_scan).distance
    d_after = bind_points(after.vertices, v_scan, f_scan).distance
    assert np.median(d_after) < 0.5 * np.median(d_before)
    assert np.median(d_after) < 0.5e-3
    # The alignment maps the whole motion: neutral frame -> the aligned vertices.
    np.testing.assert_allclose(after.apply(neutral[None])[0], after.vertices, atol=1e-12)
