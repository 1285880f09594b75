"""Stage ``fit``: the CANDIDE-style face model fitted to the tracked landmarks per frame."""

from __future__ import annotations

from typing import TYPE_CHECKING

from physanim.face.params import FitParams
from physanim.pipeline import StageContext, StageSpec

if TYPE_CHECKING:
    import numpy as np


def compute(ctx: StageContext) -> None:
    """su, au (T,n_au), pose (T,6), motion mesh (T,V,3) m, residual (T,K) m, rms (T,) m."""
    from physanim.face.fit import embed_landmarks, fit_sequence
    from physanim.face.model import load_face_model

    params: FitParams = ctx.params  # type: ignore[assignment]
    tracked = ctx.input("track")
    names = list(tracked.attrs["names"])
    points, conf = tracked["points"][...], tracked["confidence"][...]
    _check_tracked(points, conf, params)
    model = load_face_model()
    embedding = embed_landmarks(model, names, points, conf, params)
    result = fit_sequence(model, embedding, points, conf, params, progress=ctx.progress("fit"))
    ctx.write_record(result)
    ctx.write_record(embedding, prefix="embedding")
    ctx.write("triangles", model.triangles)
    ctx.out.attrs.update(
        au_names=list(model.au_names), su_names=list(model.su_names),
        vertex_names=list(model.vertex_names), landmark_names=names,
    )  # fmt: skip
    ctx.summary.update(
        rms_mm=round(float(result.rms.mean()) * 1e3, 3),
        max_rms_mm=round(float(result.rms.max()) * 1e3, 3),
    )


def _check_tracked(points: np.ndarray, confidence: np.ndarray, params: FitParams) -> None:
    """Refuse tracks (T, K, 3) m / (T, K) that cannot be fitted, saying why and what to do."""
    import numpy as np

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


SPEC = StageSpec(
    name="fit",
    upstream=("track",),
    params=FitParams,
    version="1",
    compute=compute,
    doc="rigid pose + shape units once, action units per frame -> motion mesh",
)
