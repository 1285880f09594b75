"""End to end on the demo capture: track the painted markers, lift them, fit the face model.

The demo (``physanim.capture.demo``) is generated once into a temporary directory with a
short sequence (16 frames: the expression timing is in normalised time, so jaw drop and
smile are all there).
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import zarr

from physanim.face.fit import embed_landmarks, fit_sequence
from physanim.face.landmarks import FEATURE_POINTS
from physanim.face.model import load_face_model
from physanim.face.params import FitParams
from physanim.tracking.params import TrackParams
from physanim.tracking.track import track_markers_rgbd

N_FRAMES = 16


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from physanim.capture.demo import generate_demo

    root = generate_demo(tmp_path_factory.mktemp("demo") / "demo", n_frames=N_FRAMES)
    gt = zarr.open_group(root / "ground_truth.zarr", mode="r")
    scale = json.loads((root / "rgbd" / "intrinsic.json").read_text())["depth_scale"]
    colors, depths = [], []
    for t in range(N_FRAMES):
        bgr = cv2.imread(str(root / "rgbd" / "color" / f"{t:06d}.png"))
        colors.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        raw = cv2.imread(str(root / "rgbd" / "depth" / f"{t:06d}.png"), cv2.IMREAD_UNCHANGED)
        depths.append(raw.astype(np.float64) / scale)
    return {
        "colors": colors,
        "depths": depths,
        "K": np.asarray(gt["K"][:]),
        "names": list(gt.attrs["marker_names"]),
        "template": np.asarray(gt["markers_neutral"][:]),
        "truth": np.asarray(gt["markers_camera"][:], dtype=np.float64),
        "expression": np.asarray(gt["expression"][:]),
        "expression_names": list(gt.attrs["expression_names"]),
        "fps": float(gt.attrs["fps"]),
    }


def _track(demo, colors):
    return track_markers_rgbd(
        colors, demo["depths"], demo["K"], demo["template"], demo["fps"], TrackParams()
    )


@pytest.fixture(scope="module")
def tracks(demo):
    return _track(demo, demo["colors"])


def _no_swaps(points, truth):
    """Every observed marker is closer to its own ground truth than to any other marker's."""
    d = np.linalg.norm(points[:, :, None] - truth[:, None], axis=3)  # (T, K, K)
    seen = np.isfinite(points).all(axis=2)
    return (np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2) == np.arange(d.shape[1]))[seen]


def test_markers_tracked_to_ground_truth(demo, tracks):
    err = np.linalg.norm(tracks.points - demo["truth"], axis=2)
    seen = tracks.confidence > 0
    assert seen.mean() > 0.95
    assert np.sqrt(np.mean(err[seen] ** 2)) < 1.5e-3  # m
    assert _no_swaps(tracks.points, demo["truth"]).all()
    assert np.isnan(tracks.points[~seen]).all()
    # head pose maps the actor-frame template near the observed markers (rigid part)
    pose = tracks.head_pose
    posed = np.einsum("tij,kj->tki", pose[:, :3, :3], demo["template"]) + pose[:, None, :3, 3]
    upper = [demo["names"].index(n) for n in ("glabella", "ex_L", "ex_R", "pronasale")]
    assert np.abs(posed[:, upper] - demo["truth"][:, upper]).max() < 3e-3


def test_hidden_markers_are_flagged_not_invented(demo):
    """Paint over 10 % of the dots (random frames after the first) with the skin around them."""
    K = demo["K"]
    truth = demo["truth"]
    uv = truth[..., :2] / truth[..., 2:] * [K[0, 0], K[1, 1]] + K[:2, 2]
    rng = np.random.default_rng(7)
    hidden = rng.random(truth.shape[:2]) < 0.1
    hidden[0] = False
    colors = []
    yy, xx = np.mgrid[-8:9, -8:9]
    r = np.hypot(xx, yy)
    for t, img in enumerate(demo["colors"]):
        img = img.copy()
        for u, v in np.rint(uv[t, hidden[t]]).astype(int):
            patch = img[v - 8 : v + 9, u - 8 : u + 9]
            skin = np.median(patch[(r >= 6) & (r <= 8)], axis=0)
            patch[r <= 5] = skin.astype(np.uint8)
        colors.append(img)
    tr = _track(demo, colors)
    assert (tr.confidence[hidden] == 0).all()
    assert np.isnan(tr.points[hidden]).all()
    seen = tr.confidence > 0
    err = np.linalg.norm(tr.points - truth, axis=2)
    assert np.sqrt(np.mean(err[seen] ** 2)) < 3e-3
    assert _no_swaps(tr.points, truth).all()


def test_fit_on_demo_tracks(demo, tracks):
    model = load_face_model()
    params = FitParams()
    emb = embed_landmarks(model, demo["names"], tracks.points, tracks.confidence, params)
    fit = fit_sequence(model, emb, tracks.points, tracks.confidence, params)
    fp = [demo["names"].index(n) for n in FEATURE_POINTS]
    assert np.sqrt(np.nanmean(fit.residual[:, fp] ** 2)) < 2e-3
    assert fit.motion.shape == (N_FRAMES, model.n_vertices, 3)
    ex, names = demo["expression"], demo["expression_names"]
    for au, gt in (
        ("jaw_drop", "jaw_open"),
        ("lip_corner_puller_L", "smile_L"),
        ("lip_corner_puller_R", "smile_R"),
    ):
        r = np.corrcoef(fit.au[:, model.au_names.index(au)], ex[:, names.index(gt)])[0, 1]
        assert r > 0.95, (au, r)
