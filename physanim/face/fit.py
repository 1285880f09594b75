"""Fit the face model to tracked 3D landmarks (stage ``fit``).

Rigid pose and Shape Units are fitted once to the neutral frames, then pose and Action Units
per frame. Each problem is block-coordinate descent on one objective,

    sum_k c_k |R P_k(su, au) + t - y_k|^2 + lambda |units|^2 (+ temporal term),

alternating a weighted Kabsch pose step with a bounded linear least-squares unit step
(``scipy.optimize.lsq_linear``), warm-started from the previous frame. ``P_k`` is landmark
k on the model: a barycentric blend of model vertices (an :class:`Embedding`). Landmarks are
in metres in the camera (or any) frame; the pose maps the model frame into it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear
from scipy.spatial.transform import Rotation

from physanim.face.landmarks import FEATURE_POINTS
from physanim.face.model import FaceModel, pose_matrix
from physanim.face.params import FitParams
from physanim.mesh.binding import bind_points
from physanim.transforms import cross_matrices, fit_transform


@dataclass(frozen=True)
class Embedding:
    """K landmarks on the model: ``vertices`` (K, 3) int64 indices, ``weights`` (K, 3) sums to 1."""

    vertices: np.ndarray
    weights: np.ndarray

    def apply(self, fields: np.ndarray) -> np.ndarray:
        """Blend per-vertex values (..., V, 3) -> (..., K, 3)."""
        return np.einsum("kj,...kjc->...kc", self.weights, fields[..., self.vertices, :])


def embed_vertices(model: FaceModel, names: list[str] | tuple[str, ...]) -> Embedding:
    """Embedding of landmarks that sit exactly on the named model vertices."""
    idx = model.index(names)
    w = np.zeros((len(idx), 3))
    w[:, 0] = 1.0
    return Embedding(vertices=np.repeat(idx[:, None], 3, axis=1), weights=w)


def embed_points(model: FaceModel, points: np.ndarray, su: np.ndarray | None = None) -> Embedding:
    """Embed points (K, 3) m given in the model frame at their closest points on the model."""
    b = bind_points(np.asarray(points, dtype=np.float64), model.deform(su), model.triangles)
    return Embedding(vertices=model.triangles[b.triangle], weights=b.weights)


@dataclass(frozen=True)
class NeutralFit:
    """Identity fit: ``su`` (n_su,), ``pose`` (6,) rotvec rad + t m, ``rms`` m."""

    su: np.ndarray
    pose: np.ndarray
    rms: float


@dataclass(frozen=True)
class FitResult:
    """Per-frame fit over T frames.

    ``su`` (n_su,); ``au`` (T, n_au) units; ``pose`` (T, 6) model->landmark frame (rotvec rad,
    t m); ``motion`` (T, V, 3) m, the motion mesh phi_mot(t) in the model frame (head pose
    removed); ``residual`` (T, K) m per landmark (NaN where ignored); ``rms`` (T,) m.
    """

    su: np.ndarray
    au: np.ndarray
    pose: np.ndarray
    motion: np.ndarray
    residual: np.ndarray
    rms: np.ndarray


def _check(landmarks: np.ndarray, confidence: np.ndarray, k: int) -> None:
    if landmarks.ndim != 3 or landmarks.shape[1:] != (k, 3):
        raise ValueError(f"landmarks: expected shape (T, {k}, 3) m, got {landmarks.shape}")
    if confidence.shape != landmarks.shape[:2]:
        raise ValueError(
            f"confidence: expected shape {landmarks.shape[:2]}, got {confidence.shape}"
        )


def _weights(landmarks: np.ndarray, confidence: np.ndarray, params: FitParams) -> np.ndarray:
    ok = np.isfinite(landmarks).all(axis=-1) & (confidence >= params.min_confidence)
    return np.where(ok, confidence, 0.0)


def _solve(
    base: np.ndarray,
    basis: np.ndarray,
    target: np.ndarray,
    w: np.ndarray,
    start: np.ndarray,
    bounds: tuple[float, float],
    ridge: float,
    temporal: float,
    iterations: int,
) -> tuple[np.ndarray, Rotation, np.ndarray]:
    """Fit pose and units x so that ``R (base + basis @ x) + t`` matches ``target`` (K, 3).

    ``base`` (K, 3) m, ``basis`` (n, K, 3) m per unit, ``w`` (K,) weights. Gauss-Newton on the
    joint (small rotation about the landmarks' centroid, translation, x) with x bounded by
    ``bounds``, ridge ``ridge |x|^2`` and ``temporal |x - start|^2``. The initial pose is the
    weighted Kabsch fit of ``base + basis @ start``.
    """
    n = len(basis)
    sw = np.sqrt(w)[:, None, None]
    x = start.copy()
    tr = fit_transform(base + np.tensordot(x, basis, axes=1), target, w, with_scale=False)
    rot, t = tr.rotation, tr.translation
    eye = np.eye(n)
    reg = np.hstack(
        [np.zeros((2 * n, 6)), np.vstack([eye * np.sqrt(ridge), eye * np.sqrt(temporal)])]
    )
    reg_rhs = np.concatenate([np.zeros(n), np.sqrt(temporal) * start])
    lo = np.concatenate([np.full(6, -np.inf), np.full(n, bounds[0])])
    hi = np.concatenate([np.full(6, np.inf), np.full(n, bounds[1])])
    for _ in range(iterations):
        q = (base + np.tensordot(x, basis, axes=1)) @ rot.T + t
        centre = w @ q / w.sum()
        qc = q - centre
        jac = np.zeros((len(q), 3, 6 + n))
        jac[:, :, :3] = -cross_matrices(qc)  # d(omega x qc)/d omega
        jac[:, :, 3:6] = np.eye(3)
        jac[:, :, 6:] = np.einsum("ij,nkj->kin", rot, basis)
        rhs = target - base @ rot.T - t
        a = np.vstack([(jac * sw).reshape(-1, 6 + n), reg])
        b = np.concatenate([(rhs * sw[:, :, 0]).ravel(), reg_rhs])
        z = lsq_linear(a, b, bounds=(lo, hi), method="bvls").x
        step = Rotation.from_rotvec(z[:3]).as_matrix()
        rot, t = step @ rot, step @ (t - centre) + centre + z[3:6]
        x = z[6:]
    return x, Rotation.from_matrix(rot), t


def fit_neutral(
    model: FaceModel,
    embedding: Embedding,
    landmarks: np.ndarray,
    confidence: np.ndarray,
    params: FitParams,
) -> NeutralFit:
    """Fit pose and Shape Units to the first ``params.neutral_frames`` frames.

    ``landmarks`` (T, K, 3) m, ``confidence`` (T, K) in [0, 1]; NaN landmarks are ignored.
    """
    landmarks = np.asarray(landmarks, dtype=np.float64)
    confidence = np.asarray(confidence, dtype=np.float64)
    _check(landmarks, confidence, len(embedding.vertices))
    n = min(params.neutral_frames, len(landmarks))
    w_t = _weights(landmarks[:n], confidence[:n], params)
    w = w_t.sum(axis=0)
    target = (
        np.einsum("tk,tkc->kc", w_t, np.nan_to_num(landmarks[:n])) / np.maximum(w, 1e-12)[:, None]
    )
    w = w / n
    base = embedding.apply(model.vertices)
    basis = embedding.apply(model.su)
    b = params.su_bound
    su, rot, t = _solve(
        base, basis, target, w, np.zeros(len(basis)), (-b, b), params.su_regularisation, 0.0,
        2 * params.iterations,
    )  # fmt: skip
    pts = (base + np.tensordot(su, basis, axes=1)) @ rot.as_matrix().T + t
    err = np.linalg.norm(pts - target, axis=1)
    rms = float(np.sqrt(np.sum(w * err**2) / np.sum(w)))
    return NeutralFit(su=su, pose=np.concatenate([rot.as_rotvec(), t]), rms=rms)


def fit_sequence(
    model: FaceModel,
    embedding: Embedding,
    landmarks: np.ndarray,
    confidence: np.ndarray,
    params: FitParams,
    neutral: NeutralFit | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> FitResult:
    """Fit pose and Action Units to every frame of ``landmarks`` (T, K, 3) m.

    ``confidence`` (T, K) in [0, 1] weights each landmark; NaN or low-confidence landmarks are
    ignored; a frame with fewer than 3 usable landmarks keeps the previous frame's solution.
    ``neutral`` defaults to :func:`fit_neutral` on the same data.
    """
    landmarks = np.asarray(landmarks, dtype=np.float64)
    confidence = np.asarray(confidence, dtype=np.float64)
    _check(landmarks, confidence, len(embedding.vertices))
    if neutral is None:
        neutral = fit_neutral(model, embedding, landmarks, confidence, params)
    n_frames, n_au = len(landmarks), len(model.au)
    base = embedding.apply(model.deform(neutral.su))
    basis = embedding.apply(model.au)
    weights = _weights(landmarks, confidence, params)
    au = np.zeros((n_frames, n_au))
    pose = np.zeros((n_frames, 6))
    residual = np.full(landmarks.shape[:2], np.nan)
    x, p = np.zeros(n_au), neutral.pose
    for i in range(n_frames):
        w = weights[i]
        if np.count_nonzero(w) >= 3:
            x, rot, t = _solve(
                base, basis, np.nan_to_num(landmarks[i]), w, x, (0.0, params.au_max),
                params.au_regularisation, params.au_temporal if i else 0.0, params.iterations,
            )  # fmt: skip
            p = np.concatenate([rot.as_rotvec(), t])
            pts = (base + np.tensordot(x, basis, axes=1)) @ rot.as_matrix().T + t
            residual[i] = np.where(w > 0, np.linalg.norm(pts - landmarks[i], axis=1), np.nan)
        au[i], pose[i] = x, p
        if progress is not None:
            progress(i + 1, n_frames)
    motion = model.deform(neutral.su)[None] + np.tensordot(au, model.au, axes=1)
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(np.nanmean(residual**2, axis=1))
    return FitResult(su=neutral.su, au=au, pose=pose, motion=motion, residual=residual, rms=rms)


def embed_landmarks(
    model: FaceModel,
    names: list[str] | tuple[str, ...],
    landmarks: np.ndarray,
    confidence: np.ndarray,
    params: FitParams,
    *,
    on_vertices: bool = True,
) -> Embedding:
    """Embed named landmarks on the model: feature points on their vertices, others closest.

    Landmarks named in ``FEATURE_POINTS`` sit on the model vertex of that name; the others
    (extra markers, whatever their names) are placed where their neutral position (mean of the first
    ``params.neutral_frames`` frames of ``landmarks`` (T, K, 3) m, weighted by ``confidence``
    (T, K)) meets the model after a neutral fit to the named ones. Without ``on_vertices``
    every landmark is placed so: for landmarks that are not exactly the anatomical points
    they are named after (markerless: the face mesh puts the demo actor's mouth 5-8 mm high),
    pinning them on their vertices would bend the model towards the bias.
    """
    named = np.array([n in FEATURE_POINTS for n in names])
    if named.sum() < 3:
        raise ValueError(f"names: need at least 3 of FEATURE_POINTS {FEATURE_POINTS}, got {names}")
    emb = embed_vertices(model, [n for n, ok in zip(names, named, strict=True) if ok])
    if named.all() and on_vertices:
        return emb
    neutral = fit_neutral(model, emb, landmarks[:, named], confidence[:, named], params)
    placed = ~named if on_vertices else np.ones(len(names), dtype=bool)
    n = min(params.neutral_frames, len(landmarks))
    w = _weights(landmarks[:n], confidence[:n], params)[:, placed]
    mean = np.einsum("tk,tkc->kc", w, np.nan_to_num(landmarks[:n, placed]))
    mean /= np.maximum(w.sum(axis=0), 1e-12)[:, None]
    rot, t = pose_matrix(neutral.pose)
    extra = embed_points(model, (mean - t) @ rot, neutral.su)
    vertices = np.zeros((len(names), 3), dtype=np.int64)
    weights = np.zeros((len(names), 3))
    vertices[named], weights[named] = emb.vertices, emb.weights
    vertices[placed], weights[placed] = extra.vertices, extra.weights
    return Embedding(vertices=vertices, weights=weights)
