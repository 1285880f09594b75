"""Stage ``fit``: the CANDIDE-style face model fitted to the tracked landmarks per frame."""

from __future__ import annotations

from physanim.face.params import FitParams
from physanim.pipeline import StageContext, StageSpec


def compute(ctx: StageContext) -> None:
    """su, au (T,n_au), pose (T,6), motion mesh (T,V,3) m, residual (T,K) m, rms (T,) m."""
    from physanim.face.fit import embed_landmarks, fit_sequence
    from physanim.face.model import load_face_model

    params: FitParams = ctx.params  # type: ignore[assignment]
    tracked = ctx.input("track")
    names = list(tracked.attrs["names"])
    points, conf = tracked["points"][...], tracked["confidence"][...]
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


SPEC = StageSpec(
    name="fit",
    upstream=("track",),
    params=FitParams,
    version="1",
    compute=compute,
    doc="rigid pose + shape units once, action units per frame -> motion mesh",
)
