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
distinct (stage, key), so shared stages are computed once for the whole sweep.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from physanim.config.loader import ConfigError, merge_sources, validate
from physanim.pipeline.plan import PlanEntry
from physanim.pipeline.spec import dataset_overrides


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
    return [f"{k}={json.dumps(v)}" for k, v in mapping.items()]


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
class Job:
    """One distinct stage execution of a sweep, identified by (store, stage, key)."""

    store: str
    entry: PlanEntry
    variant: str  # the first variant that needs it; its config is used to run it
    deps: tuple[tuple[str, str, str], ...]  # (store, stage, key) of upstream jobs

    @property
    def ident(self) -> tuple[str, str, str]:
        """(store, stage, key)."""
        return (self.store, self.entry.stage, self.entry.key)


def merge_plans(plans: dict[str, tuple[str, list[PlanEntry]]]) -> list[Job]:
    """One job per distinct (store, stage, key) to run, in an order where deps come first.

    ``plans`` maps variant name -> (store path, plan entries).
    """
    jobs: dict[tuple[str, str, str], Job] = {}
    for variant, (store, entries) in plans.items():
        for e in entries:
            if e.action != "run":
                continue
            ident = (store, e.stage, e.key)
            if ident not in jobs:
                deps = tuple((store, u, k) for u, k in e.upstream.items())
                jobs[ident] = Job(store, e, variant, deps)
    return list(jobs.values())
