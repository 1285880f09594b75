"""The HTML report of a face-pipeline run, assembled from the stage store.

Not a stage: it is a view over the runs the store recorded, so it can compare every variant
of ``simulate``/``evaluate`` computed so far (material models, sweeps) side by side.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physanim.render.plots import plot_mouth_corners, plot_symmetry_cost
from physanim.render.report import build_report
from physanim.store import StageStore


def variant_label(store: StageStore, evaluate_key: str) -> str:
    """Human label of an evaluate output: its material model and simulate key prefix."""
    sim_key = store.provenance("evaluate", evaluate_key)["upstream"]["simulate"]
    sim = store.provenance("simulate", sim_key)
    model = store.provenance("materials", sim["upstream"]["materials"])["params"]["model"]
    return f"{model['name']} ({sim_key[:6]})"


def shown_variants(store: StageStore) -> list[str]:
    """Evaluate keys of the complete runs recorded in the store (run manifests, sweep variants
    included), oldest first, whose materials, simulate and evaluate outputs are intact."""
    shown: list[str] = []
    for run in sorted(store.runs(), key=lambda r: r.name):
        key = run.keys.get("evaluate")
        chain = ("materials", "simulate", "evaluate")
        if (
            run.info.get("complete")
            and key not in shown
            and all(s in run.keys and store.has(s, run.keys[s]) for s in chain)
        ):
            shown.append(key)  # type: ignore[arg-type]
    return shown


def write_run_report(
    store: StageStore, entries: Sequence[Any], out_dir: Path, title: str
) -> Path | None:
    """Write ``out_dir/index.html`` for the plan ``entries`` of one run; None if not rendered."""
    keys = {e.stage: e.key for e in entries}
    if "render" not in keys or not store.has("render", keys["render"]):
        return None
    out_dir.mkdir(parents=True, exist_ok=True)
    render = store.files("render", keys["render"])
    images = [
        (caption, render / f"{stem}.png")
        for caption, stem in (
            ("Motion fidelity against the truth, per region (0 = moves like the actor)",
             "fidelity"),
            ("Lip gap: truth, FEM, kinematic scan", "lip_gap"),
            ("Jaw opening estimated from the tracked mandible landmarks", "jaw"),
            ("Symmetry cost (tracked, kinematic, FEM)", "symmetry"),
            ("Mouth-corner displacement", "mouth_corners"),
            ("FEM energies", "energies"),
        )
        if (render / f"{stem}.png").exists()
    ]  # fmt: skip
    evaluated = store.provenance("evaluate", keys["evaluate"]).get("summary", {})
    jaw_peak = evaluated.get("peak_frames", {}).get("jaw_open")
    if jaw_peak is not None and (render / "frames" / f"{jaw_peak:04d}.png").exists():
        images.insert(0, (f"Panel at the jaw-drop peak (frame {jaw_peak})",
                          render / "frames" / f"{jaw_peak:04d}.png"))  # fmt: skip
    regions = store.files("materials", keys["materials"]) / "regions.png"
    if regions.exists():
        images.append(("Material regions", regions))

    variants: dict[str, dict[str, Any]] = {}
    cost, mouth = {}, {}
    time = None
    for k in shown_variants(store):
        label = variant_label(store, k)
        ev = store.open("evaluate", k)
        summary = dict(ev.attrs.get("summary", {}))
        names = list(ev.attrs["landmark_names"])
        ch = [names.index("ch_L"), names.index("ch_R")]
        cost[label] = ev["fem/cost"][...]
        mouth[label] = ev["fem/displacement"][...][:, ch]
        fem = summary.get("fem", {})
        fidelity = summary.get("fidelity", {}).get("fem", {})
        philtrum = summary.get("philtrum_peak_mm", {})
        variants[label] = {
            "mean symmetry cost": fem.get("mean_symmetry_cost"),
            "peak mouth corner L/R (mm)": fem.get("peak_mouth_corner_mm"),
            "right / left philtrum peak (mm)": [philtrum.get("right"), philtrum.get("left")],
            **{
                f"FEM relative displacement error, {peak} peak": value.get("overall")
                for peak, value in fidelity.items()
                if isinstance(value, dict)
            },
            "surface distance RMS FEM / kinematic (mm)": [
                summary.get("surface_distance_rms_mm", {}).get("fem"),
                summary.get("surface_distance_rms_mm", {}).get("kinematic"),
            ],
            "free-region lag (s)": summary.get("free_lag_s"),
        }
        sim_key = store.provenance("evaluate", k)["upstream"]["simulate"]
        time = store.open("simulate", sim_key)["times"][...]
    if len(variants) > 1 and time is not None and len({len(c) for c in cost.values()}) == 1:
        images.append(("Symmetry cost per variant", plot_symmetry_cost(
            np.asarray(time), cost, out_dir / "variants_symmetry")[0]))  # fmt: skip
        images.append(("Mouth corners per variant", plot_mouth_corners(
            np.asarray(time), mouth, out_dir / "variants_mouth")[0]))  # fmt: skip

    key_figures: dict[str, Any] = {}
    for stage in ("track", "fit", "tetra", "simulate", "evaluate", "render"):
        if stage in keys and store.has(stage, keys[stage]):
            for name, value in store.provenance(stage, keys[stage]).get("summary", {}).items():
                if not isinstance(value, dict | list) or stage == "evaluate":
                    key_figures[f"{stage}: {name}"] = value
    stage_table = []
    for e in entries:
        if not store.has(e.stage, e.key):
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
        tables=capture_tables(
            evaluated, store.provenance("simulate", keys["simulate"]).get("summary", {})
        ),
        title=title,
        video=render / "panel.mp4",
        images=images,
        key_figures=key_figures,
        stage_table=stage_table,
        variants=variants,
        subtitle=f"store {store.root}",
    )


def capture_tables(evaluated: dict[str, Any], simulated: dict[str, Any]) -> dict[str, Any]:
    """The report's "does the simulated face perform the capture?" table from the evaluate
    and simulate summaries: relative displacement error of the FEM and the kinematic scan at
    each peak frame (whole face and per region), the lip gap against the truth, stress hot
    spots and how much of the skin the drive holds.  Empty without ground truth."""
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
    gaps = evaluated.get("lip_gap_mm", {})
    for peak in peaks:
        truth = gaps.get("truth", {}).get(peak)
        rows.append([f"lip gap at the {peak} peak (mm; truth {truth})",
                     gaps.get("fem", {}).get(peak), gaps.get("kinematic", {}).get(peak),
                     f"within 15 % of {truth}" if peak == "jaw_open" else ""])  # fmt: skip
    rows.append(["peak / 99th-percentile von Mises stress (worst frame)",
                 simulated.get("peak_to_p99_von_mises"), "", "<= 5"])  # fmt: skip
    rows.append(["fraction of the skin nodes the drive holds",
                 simulated.get("spring_node_fraction_of_skin"), "", "<= 0.25"])  # fmt: skip
    header = ("measure", "FEM", "kinematic scan", "target")
    return {"Does the simulated face perform the capture?": (header, rows)}
