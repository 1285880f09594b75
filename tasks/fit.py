"""Stage ``fit``: the CANDIDE-style face model fitted to the tracked landmarks per frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physanim.face.fit import Embedding, FitResult
from physanim.face.params import FitParams
from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.track import TrackOutput


@dataclass(frozen=True, kw_only=True)
class FitOutput(FitResult, StageOutput):
    """The face model fitted per frame: every field of ``physanim.face.fit.FitResult`` (``su``
    (n_su,); ``au`` (T, n_au); ``pose`` (T, 6) rotvec rad + t m; ``motion`` (T, V, 3) m, the
    motion mesh in the model frame; ``residual`` (T, K) m; ``rms`` (T,) m) plus the model:
    ``embedding`` of the K landmarks on the model; ``triangles`` (F, 3) of the model;
    ``au_names``, ``su_names``, ``vertex_names`` (V, named model vertices, else ""),
    ``landmark_names`` (K) the order of ``residual`` and ``embedding``.
    """

    embedding: Embedding
    triangles: np.ndarray
    au_names: list[str]
    su_names: list[str]
    vertex_names: list[str]
    landmark_names: list[str]


def compute(params: FitParams, track: TrackOutput, ctx: StageContext[FitParams]) -> FitOutput:
    """su, au (T,n_au), pose (T,6), motion mesh (T,V,3) m, residual (T,K) m, rms (T,) m."""
    from physanim.face.fit import embed_landmarks, fit_sequence
    from physanim.face.model import load_face_model

    names, points, conf = track.landmark_names, track.points, track.confidence
    _check_tracked(points, conf, params)
    model = load_face_model()
    # markerless landmarks are not exactly the points they are named after: placed by position
    markers = track.backend != "markerless"
    embedding = embed_landmarks(model, names, points, conf, params, on_vertices=markers)
    result = fit_sequence(model, embedding, points, conf, params, progress=ctx.progress("fit"))
    summary = dict(
        rms_mm=round(float(result.rms.mean()) * 1e3, 3),
        max_rms_mm=round(float(result.rms.max()) * 1e3, 3),
    )
    return FitOutput(
        **vars(result),  # the FitResult fields
        embedding=embedding, triangles=model.triangles, au_names=list(model.au_names),
        su_names=list(model.su_names), vertex_names=list(model.vertex_names),
        landmark_names=list(names), summary=summary,
    )  # fmt: skip


def _check_tracked(points: np.ndarray, confidence: np.ndarray, params: FitParams) -> None:
    """Refuse tracks (T, K, 3) m / (T, K) that cannot be fitted, saying why and what to do."""
    usable = np.isfinite(points).all(axis=2) & (confidence >= params.min_confidence)
    per_frame = usable.sum(axis=1)
    if not (per_frame >= 3).any():
        raise ValueError(
            f"no tracked points to fit: no frame of the track output has 3 landmarks with "
            f"confidence >= fit.min_confidence={params.min_confidence} (most: "
            f"{int(per_frame.max(initial=0))}); the tracker found no face: run "
            "`physanim check DATASET`"
        )
    n = min(params.neutral_frames, len(points))
    if usable[:n].any(axis=0).sum() < 3:
        first = int(np.argmax(per_frame >= 3))
        raise ValueError(
            f"the neutral fit needs 3 tracked landmarks in the first fit.neutral_frames={n} "
            f"frame(s); the face is first tracked at frame {first}: trim the recording to start "
            "with the neutral face in view"
        )


SPEC = StageSpec.typed(
    "fit",
    compute,
    version="2",
    doc="rigid pose + shape units once, action units per frame -> motion mesh",
)
