"""Parameter sweeps: expand a sweep file into variants and merge their plans into one job graph.

A sweep file (YAML)::

    pipeline: face                 # DAG name (or package.module:ATTRIBUTE)
    datasets: [demo]               # dataset names or directories
    configs: [configs/x.yaml]      # extra -c files for every variant (optional)
    set: {simulate.dt: 0.001}      # overrides for every variant (optional)
    grid:                          # cartesian product of values (optional)
      materials.model: [model1, model2, model3]
    variants:                      # and/or an explicit list of named override sets (optional)
      - {name: soft, set: {materials.scale_E: 0.5}}

Variants that share an upstream stage's key share its output: ``merge_plans`` keeps one job per
distinct (stage, key), so shared stages are computed once for the whole sweep.  A job that
fails fails the variants that use its output (``variant_errors``); the others complete.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from physanim.config.loader import ConfigError, load_config, merge_sources, validate
from physanim.pipeline.executor import Ident, Job, JobGraph, merge_plans
from physanim.pipeline.plan import PlanEntry, make_plan
from physanim.pipeline.spec import Pipeline, PipelineConfig, dataset_overrides
from physanim.store import StageStore


class NamedVariant(BaseModel):
    """One explicit variant: a name and its overrides (dotted key -> value)."""

    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1)
    configs: list[str] = Field(default_factory=list, description="extra -c files")
    set: dict[str, Any] = Field(default_factory=dict)


class SweepFile(BaseModel):
    """Schema of a sweep file (see module docstring)."""

    model_config = ConfigDict(extra="forbid")
    pipeline: str = "face"
    datasets: list[str] = Field(default_factory=lambda: ["demo"], min_length=1)
    configs: list[str] = Field(default_factory=list)
    set: dict[str, Any] = Field(default_factory=dict)
    grid: dict[str, list[Any]] = Field(default_factory=dict)
    variants: list[NamedVariant] = Field(default_factory=list)


@dataclass(frozen=True)
class Variant:
    """One run of a sweep: a dataset, config files and ``--set`` style overrides."""

    name: str
    dataset: str
    configs: tuple[str, ...]
    overrides: tuple[str, ...]


def _sets(mapping: dict[str, Any]) -> list[str]:
    # ensure_ascii=False: a character beyond U+FFFF would be written as a surrogate pair,
    # which YAML reads back as two broken characters
    return [f"{k}={json.dumps(v, ensure_ascii=False)}" for k, v in mapping.items()]


def load_sweep(path: str | Path) -> tuple[SweepFile, list[Variant]]:
    """Read and validate a sweep file and expand it into variants (datasets x grid x list)."""
    spec = validate(SweepFile, *merge_sources([path]))
    combos: list[tuple[str, list[str], dict[str, Any]]] = []
    if spec.grid:
        keys = list(spec.grid)
        for values in itertools.product(*(spec.grid[k] for k in keys)):
            name = ",".join(f"{k}={v}" for k, v in zip(keys, values, strict=True))
            combos.append((name, [], dict(zip(keys, values, strict=True))))
    combos += [(v.name, v.configs, v.set) for v in spec.variants]
    if not combos:
        combos = [("base", [], {})]
    names = [c[0] for c in combos]
    if len(set(names)) != len(names):
        raise ConfigError(f"{path}: variant names must be unique, got {names}")
    variants = [
        Variant(
            name=name if len(spec.datasets) == 1 else f"{ds}:{name}",
            dataset=ds,
            configs=(*spec.configs, *files),
            overrides=tuple(dataset_overrides(ds) + _sets(spec.set) + _sets(over)),
        )
        for ds in spec.datasets
        for name, files, over in combos
    ]
    return spec, variants


@dataclass(frozen=True)
class SweepPlan:
    """A planned sweep: its file, pipeline and variants, each variant's validated config,
    store (path) and stage keys (stage -> key), and the distinct jobs to run."""

    path: Path
    pipeline: Pipeline
    variants: list[Variant]
    configs: dict[str, PipelineConfig]
    stores: dict[str, str]
    keys: dict[str, dict[str, str]]
    jobs: list[Job]

    @property
    def graph(self) -> JobGraph:
        """The jobs as an executor runs them."""
        return JobGraph(self.pipeline, self.configs, self.jobs)

    @property
    def run_dir(self) -> Path:
        """Run directory of the first variant's dataset (sweep reports, Prefect home)."""
        return self.configs[self.variants[0].name].dataset.run_dir


def plan_sweep(
    path: str | Path,
    pipeline_of: Callable[[str], Pipeline],
    prepare: Callable[[Pipeline, PipelineConfig], None] | None = None,
) -> SweepPlan:
    """Expand a sweep file, validate every variant's config and merge their plans.

    ``pipeline_of`` turns the file's ``pipeline`` into a Pipeline (``flows.dags.get_pipeline``);
    ``prepare(pipeline, config)`` runs for each variant before it is planned (the CLI makes
    the demo dataset there, as ``run`` does). Raises ConfigError naming the file and variant
    when a variant's config is invalid.
    """
    path = Path(path)
    spec, variants = load_sweep(path)
    pipeline = pipeline_of(spec.pipeline)
    configs: dict[str, PipelineConfig] = {}
    plans: dict[str, tuple[str, list[PlanEntry]]] = {}
    for v in variants:
        try:
            cfg, _ = load_config(
                pipeline.config_model(), [pipeline.default_config, *v.configs], v.overrides
            )
        except ConfigError as exc:
            raise ConfigError(f"{path}: variant {v.name!r}: {exc}") from None
        configs[v.name] = cfg
    for v in variants:
        cfg = configs[v.name]
        if prepare is not None:
            prepare(pipeline, cfg)
        store = StageStore(cfg.dataset.store_path)
        store.remove_stale_temporaries()
        plans[v.name] = (str(store.root), make_plan(pipeline, cfg, store))
    return SweepPlan(
        path=path,
        pipeline=pipeline,
        variants=variants,
        configs=configs,
        stores={name: store for name, (store, _) in plans.items()},
        keys={name: {e.stage: e.key for e in plan} for name, (_, plan) in plans.items()},
        jobs=merge_plans(plans),
    )


def variant_errors(plan: SweepPlan, failed: Mapping[Ident, str]) -> dict[str, str]:
    """variant -> error of the first failed job whose output it needs (variants that need
    none are absent); ``failed``: (store, stage, key) -> error text."""
    errors = {}
    for v in plan.variants:
        store, keys = plan.stores[v.name], plan.keys[v.name]
        for stage in (s.name for s in plan.pipeline.stages):
            error = failed.get((store, stage, keys.get(stage, "")))
            if error is not None:
                errors[v.name] = error
                break
    return errors
