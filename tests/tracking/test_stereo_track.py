"""Stereo marker tracking: left-image tracks matched in the right image and triangulated."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from physanim.tracking.params import TrackParams
from physanim.tracking.stereo_track import match_right, read_stereo_pairs, track_markers_stereo

N_FRAMES = 8


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from physanim.capture.demo import generate_demo

    root = generate_demo(tmp_path_factory.mktemp("stereo") / "demo", n_frames=N_FRAMES)
    gt = zarr.open_group(root / "ground_truth.zarr", mode="r")
    lefts, rights, calib = read_stereo_pairs(root / "stereo")
    return {
        "lefts": lefts,
        "rights": rights,
        "calib": calib,
        "template": np.asarray(gt["markers_neutral"][:]),
        "truth": np.asarray(gt["markers_camera"][:], dtype=np.float64),
        "fps": float(gt.attrs["fps"]),
    }


def _project(points: np.ndarray, K: np.ndarray, shift_x: float = 0.0) -> np.ndarray:
    """Pixels (..., 2) of camera points (..., 3) m, camera moved by ``shift_x`` m along +x."""
    x = (points[..., 0] - shift_x) / points[..., 2]
    y = points[..., 1] / points[..., 2]
    return np.stack([K[0, 0] * x + K[0, 2], K[1, 1] * y + K[1, 2]], axis=-1)


def test_stereo_tracks_match_ground_truth(demo) -> None:
    tracks = track_markers_stereo(
        demo["lefts"], demo["rights"], demo["calib"], demo["template"], demo["fps"], TrackParams()
    )
    truth = demo["truth"]
    seen = tracks.confidence > 0
    assert seen.mean() > 0.9
    err = np.linalg.norm(tracks.points - truth, axis=2)
    assert np.isnan(tracks.points[~seen]).all()
    rms = np.sqrt(np.mean(err[seen] ** 2))
    assert rms < 0.003, f"3D RMS {rms * 1e3:.2f} mm"
    # No identity swaps: every tracked point is nearest to its own ground-truth marker.
    d = np.linalg.norm(tracks.points[:, :, None] - truth[:, None], axis=3)
    nearest = np.argmin(np.where(np.isnan(d), np.inf, d), axis=2)
    k = truth.shape[1]
    assert (nearest[seen] == np.broadcast_to(np.arange(k), seen.shape)[seen]).all()
    assert np.isfinite(tracks.head_pose[:, :3, :3]).all()


def test_a_dot_hidden_in_the_right_image_is_flagged(demo) -> None:
    calib, truth = demo["calib"], demo["truth"]
    rights = [r.copy() for r in demo["rights"]]
    hidden = (4, 10)  # (frame, marker)
    u, v = np.rint(_project(truth[hidden], calib.K1, shift_x=-calib.T[0])).astype(int)
    img = rights[hidden[0]]
    img[v - 6 : v + 7, u - 6 : u + 7] = img[v - 6, u - 12]  # skin from beside the dot
    tracks = track_markers_stereo(
        demo["lefts"], rights, calib, demo["template"], demo["fps"], TrackParams()
    )
    assert tracks.confidence[hidden] == 0.0
    assert np.isnan(tracks.points[hidden]).all()
    t = hidden[0]
    others = tracks.confidence[t] > 0
    assert others.sum() >= truth.shape[1] - 3
    assert np.linalg.norm(tracks.points[t, others] - truth[t, others], axis=1).max() < 0.006


def test_match_right_prefers_the_previous_disparity() -> None:
    params = TrackParams()
    left = np.array([[300.0, 100.0], [320.0, 150.0], [340.0, 200.0], [360.0, 250.0]])
    # Marker 0 has two dots on its row (disparity 70 and 84); its prior is 72 -> 70.
    # Marker 1 has no prior: its neighbours' median (80) picks the dot at disparity 79.
    # Marker 2's only dot is 5 px off its row; marker 3's dot jumps 20 px in disparity.
    dots = np.array([[230.0, 100.3], [216.0, 100.0], [241.0, 150.0], [260.0, 205.0], [260.0, 250]])
    prior = np.array([72.0, np.nan, 80.0, 80.0])
    out = match_right(left, dots, prior, params)
    assert np.allclose(out[0], dots[0]) and np.allclose(out[1], dots[2])
    assert np.isnan(out[2:]).all()
