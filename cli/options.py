"""Options the commands share, declared once, and the one-line error they all print.

``with_target`` gives a command the four options that select what it works on (``--pipeline``,
``--config``, ``--set``, ``--dataset``) and hands it the loaded ``Target`` instead.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

from physanim.config import ConfigError, load_config
from physanim.pipeline import Pipeline, PipelineConfig
from physanim.pipeline.spec import dataset_overrides
from physanim.store import StageStore

console = Console(stderr=True, soft_wrap=True)  # messages stay one line (no wrapping)

PipelineOpt = Annotated[
    str, typer.Option("--pipeline", "-p", help="DAG: face, ..., or package.module:ATTRIBUTE")
]
ConfigOpt = Annotated[
    list[Path] | None,
    typer.Option("--config", "-c", help="extra YAML config merged over the default (repeatable)"),
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option("--set", "-s", help="override one value: dotted.key=value (repeatable)"),
]
DatasetOpt = Annotated[
    str | None, typer.Option("--dataset", "-d", help="dataset name (data/<name>) or directory")
]


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``error: message`` (one line, no markup interpretation); returns the Exit to raise."""
    console.print(f"[red]error:[/red] {escape(message)}", highlight=False)
    return typer.Exit(code)


def get_pipeline(name: str) -> Pipeline:
    """The DAG called ``name`` (flows.dags), or a one-line error."""
    from flows.dags import get_pipeline as lookup

    try:
        return lookup(name)
    except ValueError as exc:
        raise fail(str(exc)) from None


def overrides(dataset: str | None, sets: list[str] | None) -> list[str]:
    """The overrides of ``--dataset`` then ``--set``, in the order they apply."""
    return (dataset_overrides(dataset) if dataset else []) + list(sets or [])


def load(
    pipeline: Pipeline, configs: list[Path] | None, sets: list[str] | None, dataset: str | None
) -> PipelineConfig:
    """Validated config of ``pipeline``: default file, ``-c`` files, dataset, ``--set``."""
    files = [pipeline.default_config, *(configs or [])]
    try:
        config, _ = load_config(pipeline.config_model(), files, overrides(dataset, sets))
    except ConfigError as exc:
        raise fail(str(exc)) from None
    return config


@dataclass(frozen=True)
class Target:
    """What a command works on: a pipeline, its validated config, the ``-c`` files and the
    overrides (dataset, then ``--set``) it was loaded from; ``chosen``: whether ``-c`` or
    ``--set`` chose a configuration (a command that reads the latest output by default then
    reads that configuration's)."""

    pipeline: Pipeline
    config: PipelineConfig
    configs: list[Path]
    overrides: list[str]
    chosen: bool = False

    def store(self, *, create: bool = True) -> StageStore:
        """The config's stage store; ``create=False`` for commands that only read (nothing
        is created, not even a missing dataset directory)."""
        return StageStore(self.config.dataset.store_path, create=create)


def with_target(command: Callable[..., Any]) -> Callable[..., Any]:
    """Replace ``command``'s ``target: Target`` parameter by the shared options
    ``--pipeline/--config/--set/--dataset``; the command receives the loaded Target."""
    signature = inspect.signature(command, eval_str=True)
    shared = [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=kind)
        for name, kind, default in (
            ("pipeline", PipelineOpt, "face"),
            ("config", ConfigOpt, None),
            ("set_", SetOpt, None),
            ("dataset", DatasetOpt, None),
        )
    ]
    own = [
        p.replace(kind=inspect.Parameter.KEYWORD_ONLY)
        for p in signature.parameters.values()
        if p.name != "target"
    ]

    @functools.wraps(command)
    def wrapper(
        *,
        pipeline: str,
        config: list[Path] | None,
        set_: list[str] | None,
        dataset: str | None,
        **kwargs: Any,
    ) -> Any:
        dag = get_pipeline(pipeline)
        loaded = load(dag, config, set_, dataset)
        target = Target(
            dag, loaded, list(config or []), overrides(dataset, set_), bool(config or set_)
        )
        return command(target=target, **kwargs)

    wrapper.__dict__["__signature__"] = signature.replace(parameters=[*shared, *own])
    wrapper.__annotations__ = {p.name: p.annotation for p in [*shared, *own]}
    del wrapper.__wrapped__  # typer reads the signature above, not the command's
    return wrapper
