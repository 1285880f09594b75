"""Declarations of stages and pipelines (DAGs of stages); no Prefect here."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict, Field, create_model

if TYPE_CHECKING:
    from physanim.pipeline.context import StageContext


class DatasetParams(BaseModel):
    """Where a run's inputs and outputs live (paths relative to the working directory)."""

    model_config = ConfigDict(extra="forbid")
    name: str = Field("demo", min_length=1, description="dataset name; default dir data/<name>")
    dir: str | None = Field(None, description="dataset directory; default data/<name>")
    store: str | None = Field(None, description="Zarr stage store; default <dir>/runs/store.zarr")

    @property
    def path(self) -> Path:
        """Dataset directory."""
        return Path(self.dir) if self.dir else Path("data") / self.name

    @property
    def store_path(self) -> Path:
        """Stage store directory."""
        return Path(self.store) if self.store else self.path / "runs" / "store.zarr"

    @property
    def run_dir(self) -> Path:
        """Directory for run-level files (reports, Prefect home, Dask scratch)."""
        return self.store_path.parent


def dataset_overrides(dataset: str) -> list[str]:
    """``--set`` overrides selecting a dataset by name (``data/<name>``) or by directory."""
    p = Path(dataset)
    if len(p.parts) > 1 or p.is_absolute():
        return [f"dataset.name={p.name}", f"dataset.dir={p}"]
    return [f"dataset.name={dataset}"]


@dataclass(frozen=True)
class StageSpec:
    """One stage: its name, upstream stages, params model, code version and compute function.

    ``version`` is bumped by hand whenever the stage's code changes its output; it is part of
    the content key.  ``fingerprint`` optionally returns JSON-able facts about input files
    (sizes, mtimes, hashes) that the key must also depend on.
    """

    name: str
    upstream: tuple[str, ...]
    params: type[BaseModel]
    version: str
    compute: Callable[[StageContext], None]
    doc: str = ""
    fingerprint: Callable[[DatasetParams, BaseModel], Mapping[str, Any]] | None = None

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"stage name {self.name!r} must be a Python identifier")


@dataclass(frozen=True)
class Pipeline:
    """A DAG of stages in topological order, plus its default config file."""

    name: str
    stages: tuple[StageSpec, ...]
    default_config: Path
    extra_sections: Mapping[str, type[BaseModel]] = field(default_factory=dict)
    #: called by ``run`` before planning, e.g. to generate a missing demo dataset
    prepare: Callable[[BaseModel, Any], Any] | None = None
    #: called by ``run`` after the stages, (store, plan entries, config) -> report path | None
    report: Callable[[Any, Any, BaseModel], Path | None] | None = None

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for s in self.stages:
            if s.name in seen:
                raise ValueError(f"pipeline {self.name}: stage {s.name} declared twice")
            missing = [u for u in s.upstream if u not in seen]
            if missing:
                raise ValueError(
                    f"pipeline {self.name}: stage {s.name} needs {missing} declared before it"
                )
            seen.add(s.name)

    def stage(self, name: str) -> StageSpec:
        """The stage called ``name``; ValueError listing the valid names otherwise."""
        for s in self.stages:
            if s.name == name:
                return s
        raise ValueError(
            f"pipeline '{self.name}' has no stage '{name}'; stages: "
            + ", ".join(s.name for s in self.stages)
        )

    def downstream(self, name: str) -> list[str]:
        """``name`` and every stage that depends on it, in topological order."""
        out = {name}
        for s in self.stages:
            if any(u in out for u in s.upstream):
                out.add(s.name)
        return [s.name for s in self.stages if s.name in out]

    def upstream(self, name: str) -> list[str]:
        """``name`` and every stage it depends on, in topological order."""
        out = {name}
        for s in reversed(self.stages):
            if s.name in out:
                out.update(s.upstream)
        return [s.name for s in self.stages if s.name in out]

    def config_model(self) -> type[BaseModel]:
        """Pydantic model of this pipeline's config: ``dataset`` plus one section per stage."""
        sections: dict[str, Any] = {"dataset": (DatasetParams, DatasetParams())}
        for name, model in self.extra_sections.items():
            sections[name] = (model, model())
        for s in self.stages:
            sections[s.name] = (s.params, s.params())
        return create_model(
            f"{self.name.title()}Config", __config__=ConfigDict(extra="forbid"), **sections
        )

    def mermaid(self) -> str:
        """The DAG as Mermaid flowchart text."""
        lines = ["flowchart LR"]
        lines += [f"  {s.name}[{s.name}]" for s in self.stages if not s.upstream]
        lines += [f"  {u} --> {s.name}" for s in self.stages for u in s.upstream]
        return "\n".join(lines) + "\n"

    def dot(self) -> str:
        """The DAG as Graphviz dot text."""
        lines = [f"digraph {self.name} {{", "  rankdir=LR;"]
        lines += [f'  "{s.name}";' for s in self.stages]
        lines += [f'  "{u}" -> "{s.name}";' for s in self.stages for u in s.upstream]
        return "\n".join(lines) + "\n}\n"
