"""The HTML report of a parameter sweep: every variant side by side, and where the time went.

Generic over pipelines: the measures are the stage summaries of the stages whose outputs
differ between variants (flattened to ``stage: a.b`` rows), the media are the videos and
PNG figures those stages wrote, and a timeline shows each stage run on its worker.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure as MplFigure
from matplotlib.patches import Patch

from physanim.pipeline.runner import StageResult
from physanim.render.report import build_report

#: Plain files of a stage output shown per variant
MEDIA_SUFFIXES = (".mp4", ".webm", ".png")


@dataclass(frozen=True)
class SweepVariant:
    """One variant of a sweep: its dataset, overrides, stage keys and summaries, the plain
    files (stage -> files directory) of its outputs, and its error if a stage it needs
    failed (empty: it completed)."""

    name: str
    dataset: str
    configs: tuple[str, ...]
    overrides: tuple[str, ...]
    keys: Mapping[str, str]
    summaries: Mapping[str, Mapping[str, Any]]
    files: Mapping[str, Path] = field(default_factory=dict)
    error: str = ""


def varying_stages(variants: Sequence[SweepVariant]) -> list[str]:
    """Stages whose key differs between variants (all stages if there is one variant)."""
    stages = list(dict.fromkeys(s for v in variants for s in v.keys))
    if len(variants) < 2:
        return stages
    return [s for s in stages if len({v.keys.get(s) for v in variants}) > 1]


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    """Scalars and short lists of a nested summary as ``prefix.key`` entries."""
    if isinstance(value, Mapping):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}", v, out)
    elif isinstance(value, list | tuple):
        if len(value) <= 4 and all(isinstance(x, int | float | str) for x in value):
            out[prefix] = ", ".join(f"{x:.4g}" if isinstance(x, float) else str(x) for x in value)
    else:
        out[prefix] = value


def measures(variant: SweepVariant, stages: Sequence[str]) -> dict[str, Any]:
    """The dataset, configs, overrides and summaries of ``stages`` of one variant as
    measure name -> value."""
    out: dict[str, Any] = {
        "status": f"failed: {variant.error}" if variant.error else "complete",
        "dataset": variant.dataset,
        "configs": " ".join(Path(c).name for c in variant.configs),
        "overrides": " ".join(variant.overrides),
    }
    for stage in stages:
        for name, value in variant.summaries.get(stage, {}).items():
            _flatten(f"{stage}: {name}", value, out)
    return out


def differing(
    table: Mapping[str, Mapping[str, Any]], always: Sequence[str] = ()
) -> dict[str, dict[str, Any]]:
    """variant -> measure -> value, without the measures equal in every variant (unless
    there is only one variant); ``always``: measures shown even when equal."""
    if len(table) < 2:
        return {k: dict(v) for k, v in table.items()}
    names = list(dict.fromkeys(m for v in table.values() for m in v))
    keep = [m for m in names if m in always or len({repr(v.get(m)) for v in table.values()}) > 1]
    return {k: {m: v.get(m, "") for m in keep} for k, v in table.items()}


def media(variant: SweepVariant, stages: Sequence[str]) -> list[tuple[str, Path]]:
    """(caption, path) of the videos and PNG figures that ``stages`` wrote for a variant."""
    found = []
    for stage in stages:
        folder = variant.files.get(stage)
        if folder is not None and folder.is_dir():
            found += [
                (f"{stage}: {path.name}", path)
                for path in sorted(folder.iterdir())
                if path.suffix.lower() in MEDIA_SUFFIXES
            ]
    # videos first: they are what people open a sweep report for
    return sorted(found, key=lambda item: item[1].suffix.lower() == ".png")


def plot_timeline(
    results: Sequence[StageResult], variants_of: Mapping[tuple[str, str], list[str]], stem: Path
) -> Path:
    """Gantt chart of the stage runs per worker (lanes), coloured by stage; returns the PNG.

    ``variants_of``: (stage, key) -> names of the variants that use that output.
    """
    ran = [r for r in results if r.action == "ran" and r.started > 0]
    workers = sorted({r.worker for r in ran})
    stages = list(dict.fromkeys(r.stage for r in ran))
    t0 = min((r.started for r in ran), default=0.0)
    span = max((r.started + r.seconds - t0 for r in ran), default=1.0)
    fig = MplFigure(figsize=(10, 1.6 + 0.5 * max(len(workers), 1)))
    ax = fig.subplots()
    for r in ran:
        lane = workers.index(r.worker)
        colour = f"C{stages.index(r.stage) % 10}"
        ax.barh(lane, r.seconds, left=r.started - t0, height=0.6, color=colour,
                edgecolor="white", linewidth=0.8)  # fmt: skip
        if r.seconds > 0.08 * span:  # name the variant where the bar has room for it
            names = variants_of.get((r.stage, r.key), [])
            label = names[0] if len(names) == 1 else f"{len(names)} variants"
            ax.text(r.started - t0 + 0.01 * span, lane, label, va="center", fontsize=7,
                    clip_on=True)  # fmt: skip
    ax.set_yticks(range(len(workers)), [f"worker {i + 1}" for i in range(len(workers))])
    ax.invert_yaxis()
    ax.set_xlabel("time since the first stage started (s)")
    ax.grid(axis="x", alpha=0.3)
    handles = [Patch(color=f"C{k % 10}", label=stage) for k, stage in enumerate(stages)]
    ax.legend(handles=handles, fontsize=8, ncol=min(len(stages), 6), loc="lower center",
              bbox_to_anchor=(0.5, 1.08), frameon=False)  # fmt: skip
    stem.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    png = stem.with_suffix(".png")
    fig.savefig(png, dpi=120)
    return png


def write_sweep_report(
    out_dir: Path,
    *,
    title: str,
    variants: Sequence[SweepVariant],
    results: Sequence[StageResult],
    seconds: float,
    subtitle: str = "",
) -> Path:
    """Write ``out_dir/index.html``: variants side by side, their media, the run timeline."""
    stages = varying_stages(variants)
    variants_of: dict[tuple[str, str], list[str]] = {}
    for v in variants:
        for stage, key in v.keys.items():
            variants_of.setdefault((stage, key), []).append(v.name)
    ran = [r for r in results if r.action == "ran"]
    table = {v.name: measures(v, stages) for v in variants}
    failed = [v for v in variants if v.error]
    shown = differing(table, always=("status",) if failed else ())
    key_figures = {
        "variants": len(variants),
        "failed variants": ", ".join(v.name for v in failed) or "none",
        "wall time (s)": round(seconds, 2),
        "stage runs (ran / cached)": f"{len(ran)} / {len(results) - len(ran)}",
        "stage seconds, summed": round(sum(r.seconds for r in ran), 2),
        "workers": len({r.worker for r in ran}),
        "stages that differ between variants": ", ".join(stages),
        "measures equal in every variant (not shown; see summary.json)": len(
            next(iter(table.values()), {})
        )
        - len(next(iter(shown.values()), {})),
    }
    images = []
    if any(r.started > 0 for r in ran):
        images.append(
            ("Stage runs per worker", plot_timeline(results, variants_of, out_dir / "timeline"))
        )
    stage_table = [
        {
            "stage": r.stage,
            "key": r.key[:12],
            "action": r.action,
            "seconds": round(r.seconds, 3),
            "variants": variants_of.get((r.stage, r.key), []),
            "worker": r.worker,
            "summary": dict(r.summary),
        }
        for r in results
    ]
    return build_report(
        out_dir,
        title=title,
        key_figures=key_figures,
        variants=shown,
        galleries={v.name: m for v in variants if (m := media(v, stages))},
        images=images,
        stage_table=stage_table,
        subtitle=subtitle,
    )
