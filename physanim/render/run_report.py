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
            ("Symmetry cost (tracked, kinematic, FEM)", "symmetry"),
            ("Mouth-corner displacement", "mouth_corners"),
            ("FEM energies", "energies"),
        )
    ]
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
        variants[label] = {
            "mean symmetry cost": fem.get("mean_symmetry_cost"),
            "peak mouth corner L/R (mm)": fem.get("peak_mouth_corner_mm"),
            "truth RMS FEM / kinematic (mm)": [
                summary.get("truth_rms_mm", {}).get("fem"),
                summary.get("truth_rms_mm", {}).get("kinematic"),
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
        title=title,
        video=render / "panel.mp4",
        images=images,
        key_figures=key_figures,
        stage_table=stage_table,
        variants=variants,
        subtitle=f"store {store.root}",
    )
