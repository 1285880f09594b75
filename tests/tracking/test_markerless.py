"""Markerless backend on real photos: skimage's astronaut (NASA, public domain) and its LFW
subset of small face crops."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

pytest.importorskip("ai_edge_litert", reason="markerless extra not installed")
skdata = pytest.importorskip("skimage.data", reason="scikit-image (real test photo) missing")

from physanim.face.landmarks import mirror_name  # noqa: E402
from physanim.tracking.markerless import (  # noqa: E402
    MARKERLESS_POINTS,
    MarkerlessUnavailableError,
    detect_face,
    model_dir,
    track_markerless_2d,
    track_markerless_rgbd,
)
from physanim.tracking.params import TrackParams  # noqa: E402

IDX = {n: i for i, n in enumerate(MARKERLESS_POINTS)}


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return skdata.astronaut()


@pytest.fixture(scope="module")
def points(photo: np.ndarray) -> np.ndarray:
    uv, conf = track_markerless_2d([photo], TrackParams())
    assert (conf[0] > 0.9).all()
    return uv[0]


def test_detector_finds_the_face(photo: np.ndarray) -> None:
    det = detect_face(photo, 0.5)
    assert det is not None and det.score > 0.8
    # Hand-measured face of the astronaut photo: about u 180-275, v 75-185 px.
    centre = (det.box[:2] + det.box[2:]) / 2
    assert np.allclose(centre, [226.0, 130.0], atol=12.0)
    assert det.keypoints[0, 0] < det.keypoints[1, 0]  # subject's right eye is image left


def test_feature_points_geometry(points: np.ndarray) -> None:
    v = points[:, 1]
    p = {n: points[IDX[n]] for n in MARKERLESS_POINTS}
    eyes = max(v[IDX[n]] for n in ("ex_L", "ex_R", "pi_L", "pi_R"))
    mouth = min(v[IDX[n]] for n in ("ch_L", "ch_R", "cphi_L", "cphi_R"))
    assert v[IDX["glabella"]] < eyes < v[IDX["pronasale"]] < mouth
    assert p["pi_L"][1] > p["ex_L"][1] - 3.0 and p["cphs_L"][1] < p["cphi_L"][1]
    eye_span = p["ex_L"][0] - p["ex_R"][0]
    assert 45.0 < eye_span < 80.0  # face about 100 px wide
    mid = (p["ex_L"][0] + p["ex_R"][0]) / 2
    chin = max(v[IDX[n]] for n in ("ch_L", "ch_R", "labrale_inferius"))
    assert chin < min(v[IDX[n]] for n in ("labiomental", "pogonion", "chin_3_L", "chin_3_R"))
    assert v[IDX["nasion"]] < eyes and p["labrale_inferius"][1] > p["cphi_L"][1]
    for name in MARKERLESS_POINTS:
        twin = mirror_name(name)
        if name.endswith("_L"):
            assert p[name][0] > p[twin][0] + 5.0, name  # actor's left is image right
            # mirror-symmetric about the face midline, same height
            assert abs((p[name][0] + p[twin][0]) / 2 - mid) < 0.1 * eye_span, name
            assert abs(p[name][1] - p[twin][1]) < 0.1 * eye_span, name
        elif name == twin:
            assert abs(p[name][0] - mid) < 0.1 * eye_span, name
    # Hand-marked mouth corners and pupils of the photo (px).
    assert np.allclose(p["ch_R"], [200.0, 140.0], atol=6.0)
    assert np.allclose(p["ch_L"], [246.0, 142.0], atol=6.0)
    assert p["ex_R"][0] < 203.0 < p["pi_R"][0] + 4.0
    assert p["pi_L"][0] - 4.0 < 246.0 < p["ex_L"][0]


def test_mirrored_photo_swaps_sides(photo: np.ndarray, points: np.ndarray) -> None:
    flipped = np.ascontiguousarray(photo[:, ::-1])
    uv, _ = track_markerless_2d([flipped], TrackParams())
    w = photo.shape[1]
    swapped = np.array([points[IDX[mirror_name(n)]] for n in MARKERLESS_POINTS])
    swapped[:, 0] = w - 1 - swapped[:, 0]
    assert np.abs(uv[0] - swapped).max() < 4.0


def test_tracks_a_moving_face_and_flags_a_missing_one(photo: np.ndarray) -> None:
    shifts = [0, 3, 6, 9]
    frames = [np.roll(photo, (s, 2 * s), axis=(0, 1)) for s in shifts]
    frames.insert(2, np.full_like(photo, 128))  # the face leaves for a frame
    uv, conf = track_markerless_2d(frames, TrackParams())
    assert (conf[2] == 0).all() and np.isnan(uv[2]).all()
    seen = [0, 1, 3, 4]
    assert (conf[seen] > 0.9).all()
    motion = uv[seen] - uv[0]
    expected = np.array([[2 * s, s] for s in shifts], float)[:, None, :]
    assert np.sqrt(((motion - expected) ** 2).sum(-1).mean()) < 1.5


def test_rgbd_output_matches_the_markers_backend(photo: np.ndarray) -> None:
    h, w = photo.shape[:2]
    K = np.array([[500.0, 0.0, w / 2], [0.0, 500.0, h / 2], [0.0, 0.0, 1.0]])
    depth = np.full((h, w), 0.6, np.float32)
    params = TrackParams(smoothing="none")
    tracks = track_markerless_rgbd([photo] * 3, [depth] * 3, K, 30.0, params)
    k = len(MARKERLESS_POINTS)
    assert tracks.uv.shape == (3, k, 2) and tracks.points.shape == (3, k, 3)
    assert tracks.confidence.shape == (3, k) and tracks.head_pose.shape == (3, 4, 4)
    assert np.allclose(tracks.points[..., 2], 0.6)
    x = (tracks.uv[..., 0] - K[0, 2]) / K[0, 0] * 0.6
    assert np.allclose(tracks.points[..., 0], x, atol=1e-6)
    assert np.isfinite(tracks.head_pose).all()


def test_missing_model_package_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    assert (model_dir() / "face_landmark.tflite").is_file()
    monkeypatch.setattr("importlib.util.find_spec", lambda name: None)
    with pytest.raises(MarkerlessUnavailableError, match=r"\.\[markerless\]"):
        model_dir()


def test_detects_small_real_faces_in_greyscale() -> None:
    """scikit-image's LFW subset: 100 real 25x25 greyscale face crops and 100 crops without
    a face (Labeled Faces in the Wild), padded by 4 px and enlarged to 128 px."""
    crops = skdata.lfw_subset()

    def detected(crop: np.ndarray) -> bool:
        grey = cv2.copyMakeBorder((crop * 255).astype(np.uint8), 4, 4, 4, 4, cv2.BORDER_REPLICATE)
        grey = cv2.resize(grey, (128, 128), interpolation=cv2.INTER_CUBIC)
        return detect_face(cv2.cvtColor(grey, cv2.COLOR_GRAY2RGB), 0.5) is not None

    faces = sum(detected(c) for c in crops[:100])
    others = sum(detected(c) for c in crops[100:])
    print(f"LFW subset: {faces} of 100 faces found, {others} of 100 non-faces")
    assert faces >= 95 and others <= 3
