"""Declarations of stages and pipelines (DAGs of stages); no Prefect here."""

from __future__ import annotations

import dataclasses
import inspect
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from pydantic import BaseModel, ConfigDict, Field, create_model

if TYPE_CHECKING:
    from physanim.pipeline.context import StageContext

P = TypeVar("P", bound=BaseModel)


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


class PipelineConfig(BaseModel):
    """Base of every pipeline's config model (``Pipeline.config_model``): the ``dataset``
    section is typed here, the stage sections are added per pipeline."""

    model_config = ConfigDict(extra="forbid")
    dataset: DatasetParams = Field(default_factory=DatasetParams)

    def section(self, name: str, model: type[P]) -> P:
        """The section ``name`` (a stage's params or an extra section such as ``demo``),
        checked to be a ``model``; TypeError naming both otherwise."""
        value = getattr(self, name, None)
        if not isinstance(value, model):
            raise TypeError(
                f"config section {name!r} is {type(value).__name__}, not {model.__name__}"
            )
        return value


def dataset_overrides(dataset: str) -> list[str]:
    """``--set`` overrides selecting a dataset by name (``data/<name>``) or by directory."""
    p = Path(dataset)
    if len(p.parts) > 1 or p.is_absolute():
        return [f"dataset.name={p.name}", f"dataset.dir={p}"]
    return [f"dataset.name={dataset}"]


#: what a stage's compute returns beside its arrays: JSON-able facts the CLI prints and the
#: report tabulates, stored as its output group's ``summary`` attribute
Summary = Mapping[str, Any]


@dataclass(frozen=True, kw_only=True)
class StageOutput:
    """Base of a typed stage's output dataclass: ``summary`` (JSON-able, name -> value) is
    part of the output, stored as the group's ``summary`` attribute and read back with it."""

    summary: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TypedCompute:
    """The ``compute(ctx)`` of a typed stage (what the runner calls).

    Reads each upstream output as the dataclass ``function`` declares for it, calls
    ``function(params, **upstream outputs[, ctx=ctx])``, writes the :class:`StageOutput` it
    returns and returns its summary.
    A plain frozen dataclass of module-level objects, so a stage pickles to Dask workers.
    """

    function: Callable[..., Any]
    inputs: tuple[tuple[str, type], ...]
    output: type
    wants_ctx: bool

    def __call__(self, ctx: StageContext[Any]) -> Summary:
        kwargs: dict[str, Any] = {name: ctx.read(name, cls) for name, cls in self.inputs}
        if self.wants_ctx:
            kwargs["ctx"] = ctx
        result = self.function(ctx.params, **kwargs)
        if not isinstance(result, self.output):
            raise TypeError(
                f"stage {ctx.spec.name} returned {type(result).__name__}, "
                f"declared {self.output.__name__}"
            )
        ctx.write_record(result)
        return result.summary


@dataclass(frozen=True)
class StageSpec(Generic[P]):
    """One stage: its name, upstream stages, params model, code version and compute function.

    ``compute(ctx)`` writes the output group and returns its summary (or None).

    ``version`` is bumped by hand whenever the stage's code changes its output; it is part of
    the content key.  ``fingerprint`` optionally returns JSON-able facts about input files
    (sizes, mtimes, hashes) that the key must also depend on.  ``output``: the dataclass the
    stage stores (typed stages, built by :meth:`typed`), None for a stage that writes its
    group itself.  ``files``: plain files the stage writes in its ``files/`` folder that a
    report shows, relative path -> caption (PNG figures, the MP4 video).  ``label``: names
    the variant a params value makes, for reports comparing runs (e.g. the material model).
    ``varies``: the output may differ between two runs with the same key (fTetWild's mesh):
    outputs computed from it record its content digest and read as stale once ``--force``
    has replaced it with different content.  ``section``: the stage takes its params from
    another stage's config section (the fields its params model declares), instead of a
    section of its own (e.g. ``tiles`` renders with the ``render`` section's tile size).
    """

    name: str
    upstream: tuple[str, ...]
    params: type[P]
    version: str
    compute: Callable[[StageContext[P]], Summary | None]
    doc: str = ""
    fingerprint: Callable[[DatasetParams, P], Mapping[str, Any]] | None = None
    output: type | None = None
    files: Mapping[str, str] = field(default_factory=dict)
    label: Callable[[P], str] | None = None
    varies: bool = False
    section: str | None = None

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"stage name {self.name!r} must be a Python identifier")

    def params_from(self, config: PipelineConfig) -> P:
        """This stage's params in ``config``: its own section, or the fields its params model
        declares of the ``section`` it shares."""
        value = getattr(config, self.section or self.name)
        if self.section is None:
            return value
        return self.params.model_validate(value.model_dump(include=set(self.params.model_fields)))

    @classmethod
    def typed(
        cls,
        name: str,
        compute: Callable[..., Any],
        version: str,
        doc: str = "",
        fingerprint: Callable[[DatasetParams, P], Mapping[str, Any]] | None = None,
        files: Mapping[str, str] | None = None,
        label: Callable[[Any], str] | None = None,
        varies: bool = False,
        section: str | None = None,
    ) -> StageSpec[Any]:
        """A stage from a typed function ``compute(params: P, <upstream>: <Output>, ...,
        ctx: StageContext[P]) -> Output``: its first argument's annotation is the params model,
        every further argument names an upstream stage and is annotated with that stage's
        output dataclass, an argument called ``ctx`` (optional) receives the context
        (progress, summary, files), and the return annotation is this stage's output dataclass.
        """
        hints = typing.get_type_hints(compute)
        names = list(inspect.signature(compute).parameters)
        if not names or names[0] not in hints or "return" not in hints:
            raise TypeError(f"stage {name}: compute must annotate its params and its return")
        inputs = tuple((n, hints[n]) for n in names[1:] if n != "ctx")
        output = hints["return"]
        for what, t in (("output", output), *inputs):
            if not dataclasses.is_dataclass(t):
                raise TypeError(f"stage {name}: {what} is annotated {t!r}, not a dataclass")
        if not (isinstance(output, type) and issubclass(output, StageOutput)):
            raise TypeError(f"stage {name}: its output {output!r} must subclass StageOutput")
        run = TypedCompute(compute, inputs, output, "ctx" in names)
        return cls(
            name, tuple(n for n, _ in inputs), hints[names[0]], version, run, doc,
            fingerprint, output, dict(files or {}), label, varies, section,
        )  # fmt: skip

    @property
    def inputs(self) -> Mapping[str, type]:
        """Upstream stage -> the output dataclass this stage reads from it (typed stages)."""
        return dict(self.compute.inputs) if isinstance(self.compute, TypedCompute) else {}


def describe_output(cls: type | None) -> str:
    """``Name(field, field, ...)`` of an output dataclass (the summary every output has left
    out); ``group`` for an untyped stage."""
    if cls is None:
        return "group"
    names = [f.name for f in dataclasses.fields(cls) if f.name != "summary"]
    return f"{cls.__name__}({', '.join(names)})"


@dataclass(frozen=True)
class Pipeline:
    """A DAG of stages in topological order, plus its default config file."""

    name: str
    stages: tuple[StageSpec, ...]
    default_config: Path
    extra_sections: Mapping[str, type[BaseModel]] = field(default_factory=dict)
    #: called by ``run`` before planning, e.g. to generate a missing demo dataset:
    #: (config, progress, starting) with ``starting()`` called when there is work to do
    prepare: Callable[..., Any] | None = None
    #: called by ``run`` after the stages, (store, plan entries, config) -> report path | None
    report: Callable[[Any, Any, PipelineConfig], Path | None] | None = None

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
            for u, wanted in s.inputs.items():
                given = self.stage(u).output
                if given is not wanted:
                    raise ValueError(
                        f"pipeline {self.name}: stage {s.name} reads {u} as "
                        f"{getattr(wanted, '__name__', wanted)}, but {u} stores "
                        f"{getattr(given, '__name__', given)}"
                    )
            if s.section is not None:
                owner = next((o for o in self.stages if o.name == s.section), None)
                extra = set(s.params.model_fields) - set(owner.params.model_fields if owner else ())
                if owner is None or owner.section is not None or extra:
                    raise ValueError(
                        f"pipeline {self.name}: stage {s.name} shares section {s.section!r}, "
                        "which must be another stage's own section with every field "
                        f"{s.params.__name__} declares"
                        + (f" (lacks {sorted(extra)})" if extra else "")
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

    def config_model(self) -> type[PipelineConfig]:
        """Pydantic model of this pipeline's config: ``dataset`` plus one section per stage."""
        sections: dict[str, Any] = {}
        for name, model in self.extra_sections.items():
            sections[name] = (model, model())
        for s in self.stages:
            if s.section is None:  # a stage sharing another's section adds none
                sections[s.name] = (s.params, s.params())
        return create_model(f"{self.name.title()}Config", __base__=PipelineConfig, **sections)

    def edges(self) -> list[tuple[str, str, type | None]]:
        """(upstream, stage, output dataclass the edge carries; None: an untyped group)."""
        return [(u, s.name, self.stage(u).output) for s in self.stages for u in s.upstream]

    def text(self) -> str:
        """The DAG as text: each stage, its version, doc, and what each incoming edge carries."""
        out = []
        for s in self.stages:
            settings = f", settings: {s.section}" if s.section else ""
            out.append(
                f"{s.name} (v{s.version}{settings})" + (f": {s.doc}" if s.doc else "") + "\n"
            )
            out += [f"  <- {u}: {describe_output(self.stage(u).output)}\n" for u in s.upstream]
        return "".join(out)

    def mermaid(self) -> str:
        """The DAG as Mermaid flowchart text, each edge labelled with the dataclass it carries."""
        lines = ["flowchart LR"]
        lines += [f"  {s.name}[{s.name}]" for s in self.stages if not s.upstream]
        lines += [f"  {u} -->{_label(t, '|')} {s}" for u, s, t in self.edges()]
        return "\n".join(lines) + "\n"

    def dot(self) -> str:
        """The DAG as Graphviz dot text, each edge labelled with the dataclass it carries."""
        lines = [f"digraph {self.name} {{", "  rankdir=LR;"]
        lines += [f'  "{s.name}";' for s in self.stages]
        lines += [
            f'  "{u}" -> "{s}"' + (f' [label="{t.__name__}"]' if t else "") + ";"
            for u, s, t in self.edges()
        ]
        return "\n".join(lines) + "\n}\n"


def _label(output: type | None, bar: str) -> str:
    return f"{bar}{output.__name__}{bar}" if output is not None else ""
