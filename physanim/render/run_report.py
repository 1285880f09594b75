"""The HTML report of a face-pipeline run, assembled from the stage store.

Not a stage: it is a view over the runs the store recorded, so it can compare every variant
computed so far (material models, sweeps) side by side.  It is driven by what the stages
declare, never by their names: the files each stage shows (``StageSpec.files``: figures and
the video), the summaries they record, the stage whose output is a
:class:`~physanim.evaluate.face.FaceEvaluation` (compared across runs), the stage it evaluates
(its last upstream, whose summary and key the report quotes) and the stages that name a
variant (``StageSpec.label``).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from physanim.evaluate.face import FaceEvaluation
from physanim.pipeline.spec import Pipeline, StageSpec
from physanim.render.plots import plot_mouth_corners, plot_symmetry_cost
from physanim.render.report import build_report
from physanim.store import StageStore


def evaluation_stage(pipeline: Pipeline) -> StageSpec[Any] | None:
    """The stage whose output is a FaceEvaluation (None: the pipeline has none)."""
    return next(
        (
            s
            for s in pipeline.stages
            if isinstance(s.output, type) and issubclass(s.output, FaceEvaluation)
        ),
        None,
    )


def variant_label(pipeline: Pipeline, store: StageStore, key: str) -> str:
    """Human label of an evaluation output: the labels its upstream stages declare for their
    params (e.g. the material model), and the key prefix of the output it evaluates."""
    spec = evaluation_stage(pipeline)
    assert spec is not None
    upstream = store.provenance(spec.name, key)["upstream"]
    labels = []
    for s in pipeline.stages:
        if s.label is not None and s.name in upstream:
            labels.append(
                s.label(
                    s.params.model_validate(store.provenance(s.name, upstream[s.name])["params"])
                )
            )
    evaluated = upstream[spec.upstream[-1]]
    return f"{' '.join(labels)} ({evaluated[:6]})"


def shown_variants(store: StageStore, chain: Sequence[str]) -> list[str]:
    """Keys of the last stage of ``chain`` in the complete runs recorded in the store (run
    manifests, sweep variants included), oldest first, whose ``chain`` outputs are intact."""
    shown: list[str] = []
    intact = cache(store.has)  # the runs share most upstream outputs: check each once
    for run in sorted(store.runs(), key=lambda r: r.name):
        key = run.keys.get(chain[-1])
        if (
            key is not None
            and run.info.get("complete")
            and key not in shown
            and all(s in run.keys and intact(s, run.keys[s]) for s in chain)
        ):
            shown.append(key)
    return shown


def recent_variants(shown: Sequence[str], current: str | None, limit: int) -> list[str]:
    """The last ``limit`` of ``shown`` (oldest first), ending with ``current`` when given (a
    run that recomputed nothing keeps its first place among the recorded runs)."""
    others = [k for k in shown if k != current]
    if current is None:
        return others[max(0, len(others) - limit) :]
    return [*others[max(0, len(others) - limit + 1) :], current]


def variant_row(summary: dict[str, Any]) -> dict[str, Any]:
    """One column of the variants table from an evaluation's summary."""
    fem = summary.get("fem", {})
    fidelity = summary.get("fidelity", {}).get("fem", {})
    philtrum = summary.get("philtrum_peak_mm", {})
    surface = summary.get("surface_distance_rms_mm", {})
    return {
        "mean symmetry cost": fem.get("mean_symmetry_cost"),
        "peak mouth corner L/R (mm)": fem.get("peak_mouth_corner_mm"),
        "right / left philtrum peak (mm)": [philtrum.get("right"), philtrum.get("left")],
        **{
            f"FEM relative displacement error, {peak} peak": value.get("overall")
            for peak, value in fidelity.items()
            if isinstance(value, dict)
        },
        "surface distance RMS FEM / kinematic (mm)": [surface.get("fem"), surface.get("kinematic")],
        "free-region lag (s)": summary.get("free_lag_s"),
        **{
            f"FEM behind the capture, {region} (ms)": summary.get("lag_behind_capture_ms", {}).get(
                region
            )
            for region in ("overall", "Cheek")
        },
    }


def write_run_report(
    pipeline: Pipeline, store: StageStore, entries: Sequence[Any], out_dir: Path, title: str
) -> Path | None:
    """Write ``out_dir/index.html`` for the plan ``entries`` of one run; None if no stage
    declaring a video has its output."""
    keys = {e.stage: e.key for e in entries if store.has(e.stage, e.key)}
    shown = [s for s in pipeline.stages if s.name in keys]
    videos = [(s, f) for s in shown for f in s.files if f.endswith(".mp4")]
    video = next(
        (store.files(s.name, keys[s.name]) / f for s, f in videos
         if (store.files(s.name, keys[s.name]) / f).exists()),
        None,
    )  # fmt: skip
    if video is None:
        return None
    out_dir.mkdir(parents=True, exist_ok=True)
    images = [
        (caption, store.files(s.name, keys[s.name]) / f)
        for s in reversed(shown)
        for f, caption in s.files.items()
        if f.endswith(".png") and (store.files(s.name, keys[s.name]) / f).exists()
    ]
    spec = evaluation_stage(pipeline)
    evaluated: dict[str, Any] = {}
    simulated: dict[str, Any] = {}
    variants: dict[str, dict[str, Any]] = {}
    if spec is not None and spec.name in keys:
        evaluated = store.provenance(spec.name, keys[spec.name]).get("summary", {})
        target = spec.upstream[-1]
        simulated = (
            store.provenance(target, keys[target]).get("summary", {}) if target in keys else {}
        )
        peak = evaluated.get("peak_frames", {}).get("jaw_open")
        panel = video.parent / "frames" / f"{peak:04d}.png" if peak is not None else None
        if panel is not None and panel.exists():
            images.insert(0, (f"Panel at the jaw-drop peak (frame {peak})", panel))
        variants = _compare_variants(pipeline, spec, store, out_dir, images, keys[spec.name])

    warnings = [
        f"{s.name}: {w}"
        for s in shown
        for w in store.provenance(s.name, keys[s.name]).get("summary", {}).get("warnings", [])
    ]
    key_figures: dict[str, Any] = {}
    for s in shown:
        for name, value in store.provenance(s.name, keys[s.name]).get("summary", {}).items():
            if not isinstance(value, dict | list) or s is spec:
                key_figures[f"{s.name}: {name}"] = value
    stage_table = []
    for e in entries:
        if e.stage not in keys:
            continue
        prov = store.provenance(e.stage, e.key)
        stage_table.append(
            {
                "stage": e.stage,
                "key": e.key[:12],
                "action": e.action,
                "seconds": prov.get("duration_s"),
                "params": prov.get("params", {}),
                "provenance": {
                    k: prov.get(k)
                    for k in ("version", "upstream", "physanim_version", "host", "started")
                },
            }
        )
    return build_report(
        out_dir,
        viewer=_viewer(store, shown, keys, out_dir),
        tables=capture_tables(evaluated, simulated),
        title=title,
        video=video,
        images=images,
        key_figures=key_figures,
        stage_table=stage_table,
        variants=variants,
        warnings=warnings,
        subtitle=f"store {store.root}",
    )


#: The exported glTF files the viewer plays, by file stem, and their labels in it.
VIEWER_MODELS = {"fem": "FEM", "capture": "captured scan"}
#: The evaluate output's per-vertex errors of each of them (where the run has a truth).
VIEWER_ERRORS = {"FEM": "scan_error_fem", "captured scan": "scan_error_kinematic"}


def _viewer(
    store: StageStore, shown: Sequence[StageSpec[Any]], keys: dict[str, str], out_dir: Path
) -> Path | str | None:
    """The report's 3D viewer of the glTF files a shown stage wrote (the export stage's), or
    why there is none (three.js missing), or None where no stage wrote one."""
    from physanim.render.viewer import THREE_MISSING, three_available, write_viewer

    for s in shown:
        folder = store.files(s.name, keys[s.name])
        found = {label: folder / f"{stem}.glb" for stem, label in VIEWER_MODELS.items()}
        found = {label: path for label, path in found.items() if path.is_file()}
        if found:
            if not three_available():
                return THREE_MISSING
            return write_viewer(out_dir, found, colours=_error_colours(store, keys))
    return None


def _error_colours(store: StageStore, keys: dict[str, str]) -> dict[str, tuple[Any, str]]:
    """Viewer label -> ((N, 3) uint8 colours, legend) of each scan vertex's largest error
    against the truth, from the evaluate output (none without a truth or an evaluate)."""
    from physanim.render.face_panel import TileParams

    if "evaluate" not in keys or not store.has("evaluate", keys["evaluate"]):
        return {}
    group = store.open("evaluate", keys["evaluate"])
    out = {}
    for label, name in VIEWER_ERRORS.items():
        if name in group:
            error_mm = 1e3 * np.asarray(group[name][...], dtype=np.float64)
            colour_map = TileParams().error_colours(error_mm[None])
            top = colour_map.clim[1]
            legend = (
                f"largest error vs truth: white 0 to purple {top:.2f} mm and above; grey: no "
                "truth (a hole of the actor's scan)"
            )
            out[label] = (colour_map.colours(error_mm), legend)
    return out


#: Variants the run report compares: the most recent runs' (a store holds every edit ever run).
MAX_VARIANTS = 8


def _compare_variants(
    pipeline: Pipeline,
    spec: StageSpec[Any],
    store: StageStore,
    out_dir: Path,
    images: list[tuple[str, Path]],
    this: str,
) -> dict[str, dict[str, Any]]:
    """The variants table (label -> row) of the last ``MAX_VARIANTS`` recorded runs'
    evaluations by the current code version, this run's (key ``this``) last; with more than
    one, their symmetry cost and mouth corners plotted together (appended to ``images``)."""
    variants: dict[str, dict[str, Any]] = {}
    cost, mouth = {}, {}
    time = None
    current = [
        k
        for k in shown_variants(store, pipeline.upstream(spec.name))
        if store.provenance(spec.name, k).get("version") == spec.version
    ]  # another code version wrote another output layout
    for k in recent_variants(current, this, MAX_VARIANTS):
        label = variant_label(pipeline, store, k)
        group = store.open(spec.name, k)
        fem = group["fem"]  # the FEM's landmark measures alone (a whole evaluation: 0.2 s)
        cost[label] = fem["cost"][...]
        mouth[label] = fem["displacement"].get_orthogonal_selection(
            (slice(None), group.attrs["mouth_corners"])
        )
        variants[label] = variant_row(dict(group.attrs.get("summary", {})))
        time = group["times"][...]
    if len(variants) > 1 and time is not None and len({len(c) for c in cost.values()}) == 1:
        images.append(("Symmetry cost per variant", plot_symmetry_cost(
            np.asarray(time), cost, out_dir / "variants_symmetry")[0]))  # fmt: skip
        images.append(("Mouth corners per variant", plot_mouth_corners(
            np.asarray(time), mouth, out_dir / "variants_mouth")[0]))  # fmt: skip
    return variants


def capture_tables(evaluated: dict[str, Any], simulated: dict[str, Any]) -> dict[str, Any]:
    """The report's "does the simulated face perform the capture?" table from the evaluate
    and simulate summaries: relative displacement error of the FEM and the kinematic scan at
    each peak frame (whole face and per region), the lip gap against the truth, the moved
    scan's silhouettes and triangle stretch, stress hot spots, tets turned inside out and how
    much of the skin the drive holds.  Empty without ground truth."""
    fidelity = evaluated.get("fidelity")
    if not fidelity:
        return {}
    rows: list[list[Any]] = []
    peaks = evaluated.get("peak_frames", {})
    for peak, frame in peaks.items():
        for part in fidelity["fem"][peak]:
            rows.append([
                f"relative displacement error at the {peak} peak (frame {frame}), "
                + ("whole face" if part == "overall" else part.replace("_", " & ")),
                fidelity["fem"][peak][part], fidelity["kinematic"][peak][part],
                "<= 0.15" if part == "overall" else "",
            ])  # fmt: skip
    rows.append(["worst frame's relative displacement error", fidelity["fem"]["worst"],
                 fidelity["kinematic"]["worst"], ""])  # fmt: skip
    if missing := evaluated.get("points_without_truth", {}).get("sample"):
        rows.append(["sampled scan vertices with no true skin under them (holes of the actor's "
                     "scan that the scan stage filled), left out of the errors above",
                     missing, missing, ""])  # fmt: skip
    gaps = evaluated.get("lip_gap_mm", {})
    for peak in peaks:
        truth = gaps.get("truth", {}).get(peak)
        rows.append([f"lip gap at the {peak} peak (mm; truth {truth})",
                     gaps.get("fem", {}).get(peak), gaps.get("kinematic", {}).get(peak),
                     f"within 15 % of {truth}" if peak == "jaw_open" else ""])  # fmt: skip
    surfaces = evaluated.get("surfaces", {})
    for view in surfaces.get("fem", {}).get("silhouette_iou_min", {}):
        name = "front" if float(view) == 0 else f"turned {view} deg"
        rows.append([f"silhouette against the truth's, worst frame ({name}; 1 = same outline)",
                     surfaces["fem"]["silhouette_iou_min"][view],
                     surfaces["kinematic"]["silhouette_iou_min"][view], ">= 0.98"])  # fmt: skip
    if surfaces:
        truth = surfaces.get("truth", {}).get("max_stretch_at_peaks")
        rows.append([f"largest stretch of a scan triangle off the lip seam (the truth's own at "
                     f"the peaks: {truth})",
                     surfaces["fem"]["max_stretch"], surfaces["kinematic"]["max_stretch"],
                     ""])  # fmt: skip
        rows.append(["scan triangles turned over (off the lip seam, worst frame)",
                     surfaces["fem"]["inverted_max"], surfaces["kinematic"]["inverted_max"],
                     "0"])  # fmt: skip
    rows.append(["peak / 99th-percentile von Mises stress (worst frame)",
                 simulated.get("peak_to_p99_von_mises"), "", "<= 5"])  # fmt: skip
    # a linear law follows a lip stretched past twice its height only by turning tets under
    # the seam inside out (docs/VALIDATION.md): shown, so the price of a fit is in sight
    rows.append(["tets turned inside out (in any frame)",
                 simulated.get("inverted_tets"), "", "0"])  # fmt: skip
    for peak, count in evaluated.get("inverted_tets_at_peaks", {}).items():
        rows.append([f"tets turned inside out at the {peak} peak", count, "", "0"])
    rows.append(["fraction of the skin nodes the drive holds",
                 simulated.get("spring_node_fraction_of_skin"), "", "<= 0.25"])  # fmt: skip
    header = ("measure", "FEM", "captured scan", "target")
    return {"Does the simulated face perform the capture?": (header, rows)}
