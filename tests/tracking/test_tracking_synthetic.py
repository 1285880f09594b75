"""Detection, labelling, tracking, lifting and smoothing against exact synthetic answers."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.tracking.detect import detect_markers
from physanim.tracking.label import assign, label_markers
from physanim.tracking.lift import backproject, lift_depth, sample_depth, triangulate_rectified
from physanim.tracking.params import TrackParams
from physanim.tracking.smooth import kalman_rts, one_euro
from physanim.tracking.track import track_markers_2d
from physanim.transforms import fit_transform

from .synthetic import draw, template

K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])


def _rot(a):
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def test_detection_is_subpixel_accurate():
    rng = np.random.default_rng(0)
    centres = template() + [320.3, 241.7] + rng.uniform(-0.5, 0.5, (30, 2))
    found = detect_markers(draw(centres), TrackParams())
    assert len(found) == len(centres)
    d = np.linalg.norm(found[:, None] - centres[None], axis=2).min(axis=1)
    assert d.mean() < 0.2 and d.max() < 0.35  # px


def test_detection_roi_and_empty_image():
    centres = template() + [320.0, 240.0]
    img = draw(centres)
    found = detect_markers(img, TrackParams(), roi=(0, 0, 320, 480))
    assert len(found) == np.sum(centres[:, 0] < 317) and (found[:, 0] < 320).all()
    assert detect_markers(draw(np.zeros((0, 2))), TrackParams()).shape == (0, 2)
    with pytest.raises(ValueError, match="RGB"):
        detect_markers(img[..., 0], TrackParams())


@pytest.mark.parametrize("dim", [2, 3])
def test_fit_transform_recovers_similarity(dim):
    rng = np.random.default_rng(dim)
    src = rng.normal(size=(20, dim))
    q, _ = np.linalg.qr(rng.normal(size=(dim, dim)))
    q[:, 0] *= np.sign(np.linalg.det(q))  # a rotation, not a reflection
    dst = 1.7 * src @ q.T + rng.normal(size=dim)
    tr = fit_transform(src, dst)
    np.testing.assert_allclose(tr.apply(src), dst, atol=1e-10)
    assert tr.scale == pytest.approx(1.7)
    w = np.ones(20)
    w[:5] = 0.0
    dst[:5] += 10.0  # zero-weight outliers are ignored
    np.testing.assert_allclose(fit_transform(src, dst, w).rotation, q, atol=1e-10)


def test_labelling_recovers_identities_with_outliers_and_missing_dots():
    tpl = template()
    truth = 2.3 * tpl @ _rot(np.radians(12)).T + [330.0, 250.0]
    keep = np.ones(len(tpl), bool)
    keep[[3, 17]] = False  # two markers not detected
    rng = np.random.default_rng(1)
    spurious = rng.uniform([150, 100], [500, 400], (4, 2))  # four false dots
    dets = np.vstack([truth[keep], spurious])
    order = rng.permutation(len(dets))
    dets = dets[order]
    match, tr = label_markers(tpl, dets, gate=12.0)
    expected = np.full(len(tpl), -1)
    expected[np.nonzero(keep)[0]] = np.argsort(order)[: keep.sum()]
    np.testing.assert_array_equal(match, expected)
    assert tr.scale == pytest.approx(2.3, rel=1e-6)


def test_assign_respects_gate_and_nan():
    pred = np.array([[0.0, 0.0], [10.0, 0.0], [np.nan, np.nan]])
    dets = np.array([[10.5, 0.0], [0.4, 0.0], [50.0, 0.0]])
    np.testing.assert_array_equal(assign(pred, dets, 2.0), [1, 0, -1])
    np.testing.assert_array_equal(assign(pred, dets, 0.45), [1, -1, -1])


def test_tracking_keeps_identities_and_flags_hidden_markers():
    tpl = template()
    n_t = 12
    t = np.arange(n_t)[:, None, None]
    wobble = 3.0 * np.sin(t / 3.0 + tpl[None, :, :1] / 100.0)  # smooth non-rigid motion, px
    centres = 2.0 * tpl[None] + [320.0, 240.0] + 2.5 * t * np.array([1.0, -0.5]) + wobble
    rng = np.random.default_rng(3)
    hidden = rng.random((n_t, len(tpl))) < 0.1
    hidden[0] = False
    frames = [draw(centres[i], seed=i, hidden=set(np.nonzero(hidden[i])[0])) for i in range(n_t)]
    uv, conf = track_markers_2d(frames, tpl, TrackParams())
    assert (conf[hidden] == 0).all() and np.isnan(uv[hidden]).all()  # flagged, not invented
    assert (conf[~hidden] == 1).all()
    err = np.linalg.norm(uv[~hidden] - centres[~hidden], axis=1)
    assert err.max() < 0.35  # px (detection accuracy): every visible marker kept its identity


def test_depth_sampling_rejects_invalid_pixels_and_lifts_exactly():
    h, w = 480, 640
    vv, uu = np.mgrid[0:h, 0:w].astype(float)
    depth = 0.5 + 1e-4 * (uu - 320)  # a tilted plane, m
    depth[200:203, 300:303] = 0.0  # invalid pixels (zeros and NaN)
    depth[240, 330] = np.nan
    uv = np.array([[301.0, 201.0], [330.0, 240.0], [10.0, 10.0], [np.nan, 1.0], [700.0, 1.0]])
    z = sample_depth(depth, uv, 5)
    np.testing.assert_allclose(z[:3], 0.5 + 1e-4 * (uv[:3, 0] - 320), atol=1e-12)
    assert np.isnan(z[3:]).all()
    pts = lift_depth(uv[:3], depth, K, 5)
    proj = pts[:, :2] / pts[:, 2:] * 600.0 + [320.0, 240.0]
    np.testing.assert_allclose(proj, uv[:3], atol=1e-9)


def test_stereo_triangulation_is_exact():
    rng = np.random.default_rng(4)
    pts = rng.uniform([-0.05, -0.05, 0.4], [0.05, 0.05, 0.6], (10, 3))
    left = pts[:, :2] / pts[:, 2:] * 600.0 + [320.0, 240.0]
    right = (pts[:, :2] - [0.06, 0.0]) / pts[:, 2:] * 600.0 + [320.0, 240.0]
    np.testing.assert_allclose(triangulate_rectified(left, right, K, 0.06), pts, atol=1e-12)
    np.testing.assert_allclose(backproject(left, pts[:, 2], K), pts, atol=1e-12)


def test_smoothers_reduce_noise_without_lag():
    fps, n = 30.0, 120
    t = np.arange(n) / fps
    truth = np.stack([0.01 * np.sin(2 * np.pi * 0.7 * t), 0.02 * t], axis=1)  # m
    rng = np.random.default_rng(5)
    noisy = truth + rng.normal(0, 5e-4, truth.shape)
    noisy[50:53, 0] = np.nan
    ks = kalman_rts(noisy, fps, accel_std=0.3, meas_std=5e-4)
    assert np.isnan(ks[50:53, 0]).all() and np.isfinite(ks[50:53, 1]).all()
    ok = np.isfinite(ks)
    raw_err = np.sqrt(np.mean((noisy[ok] - truth[ok]) ** 2))
    ks_err = np.sqrt(np.mean((ks[ok] - truth[ok]) ** 2))
    assert ks_err < 0.6 * raw_err
    assert abs(np.mean((ks - truth)[10:-10, 1])) < 1e-4  # no lag on the ramp (m)
    oe = one_euro(noisy, fps, min_cutoff=3.0, beta=500.0)
    assert np.isnan(oe[50:53, 0]).all()
    lag = np.mean((oe - truth)[20:, 1])
    slow = np.mean((one_euro(noisy, fps, min_cutoff=3.0, beta=0.0) - truth)[20:, 1])
    assert abs(lag) < 3e-4 < abs(slow)  # the speed term removes most of the lag (< 0.3 mm)


def test_frames_without_a_face_are_warned_about():
    """A tracker that loses more than a few percent of the frames says so (the markerless
    demo found a face in 63 % of them and the run looked normal); one frame in 40 lost is
    within the margin."""
    from physanim.tracking.checks import check_tracks
    from physanim.tracking.tracks import Tracks

    template = np.random.default_rng(1).normal(scale=0.03, size=(12, 3))
    points = np.repeat(template[None] + [0, 0, 0.5], 40, axis=0)
    confidence = np.ones((40, 12))

    def warnings(lost_frames: int) -> list[str]:
        conf = confidence.copy()
        conf[:lost_frames] = 0.0
        pts = np.where(conf[..., None] > 0, points, np.nan)
        tracks = Tracks(np.zeros((40, 12, 2)), pts, conf, np.tile(np.eye(4), (40, 1, 1)))
        return check_tracks(tracks, template, "markers", "the template")

    assert warnings(1) == []
    found = warnings(4)
    assert len(found) == 1 and "a face was found in only 36 of 40 frames (90%)" in found[0]
