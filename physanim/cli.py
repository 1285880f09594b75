"""The ``physanim`` command line: run, status, dag, show, clean.

The CLI is the application's entry point: it loads the DAG declarations from ``tasks/`` and,
for ``run``, the Prefect flow from ``flows/`` (imported lazily, so ``status``, ``dag``, ``show``
and ``clean`` never need Prefect).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Annotated

import typer
from pydantic import BaseModel
from rich.console import Console
from rich.table import Table

from physanim.config import ConfigError, load_config
from physanim.pipeline import Pipeline, PlanEntry, StageFailed, StageResult, make_plan
from physanim.pipeline.spec import dataset_overrides
from physanim.store import StageOutputMissing, StageStore

app = typer.Typer(
    add_completion=False, no_args_is_help=True, help=__doc__, pretty_exceptions_enable=False
)
console = Console(stderr=True)

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
OnlyOpt = Annotated[str | None, typer.Option("--only", help="run just this stage")]
FromOpt = Annotated[str | None, typer.Option("--from", help="run this stage and its downstream")]
ForceOpt = Annotated[
    list[str] | None, typer.Option("--force", help="recompute this stage even if cached")
]


def _pipeline(name: str) -> Pipeline:
    from flows.dags import get_pipeline

    try:
        return get_pipeline(name)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


def load(
    pipeline: Pipeline, configs: list[Path] | None, sets: list[str] | None, dataset: str | None
) -> BaseModel:
    """Validated config of ``pipeline``: default file, ``-c`` files, dataset, ``--set``."""
    files = [pipeline.default_config, *(configs or [])]
    overrides = (dataset_overrides(dataset) if dataset else []) + list(sets or [])
    try:
        config, _ = load_config(pipeline.config_model(), files, overrides)
    except ConfigError as exc:
        console.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    return config


def _plan(
    pipeline: Pipeline,
    config: BaseModel,
    only: str | None,
    start: str | None,
    force: list[str] | None,
) -> tuple[StageStore, list[PlanEntry]]:
    store = StageStore(config.dataset.store_path)  # type: ignore[attr-defined]
    try:
        entries = make_plan(pipeline, config, store, only=only, start=start, force=force or ())
    except ValueError as exc:
        console.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    return store, entries


def _plan_table(entries: list[PlanEntry]) -> Table:
    table = Table(title="plan")
    for col in ("stage", "key", "action", "why"):
        table.add_column(col)
    colour = {"cached": "green", "run": "yellow", "skip": "dim"}
    for e in entries:
        action = "will run" if e.action == "run" else e.action
        table.add_row(e.stage, e.key[:12], f"[{colour[e.action]}]{action}", e.reason)
    return table


def _log_result(r: StageResult) -> None:
    if r.action == "cached":
        console.print(f"[green]{r.stage}[/green]: cached ({r.key[:12]})")
    else:
        console.print(f"[yellow]{r.stage}[/yellow]: ran in {r.seconds:.2f} s ({r.key[:12]})")
        for warning in r.summary.get("warnings", ()):
            console.print(f"[yellow]warning:[/yellow] {warning}", highlight=False)


@app.command()
def run(
    pipeline: PipelineOpt = "face",
    config: ConfigOpt = None,
    set_: SetOpt = None,
    dataset: DatasetOpt = None,
    only: OnlyOpt = None,
    start: FromOpt = None,
    force: ForceOpt = None,
    local: Annotated[
        bool, typer.Option("--local", help="run stages in this process without Prefect")
    ] = False,
) -> None:
    """Run the DAG (or part of it); cached stages are reused."""
    t0 = time.perf_counter()
    dag = _pipeline(pipeline)
    cfg = load(dag, config, set_, dataset)
    from physanim.pipeline.progress import rich_progress

    if dag.prepare is not None:
        with rich_progress(console) as progress:
            made = dag.prepare(cfg, progress)
        if made:
            console.print(f"generated {made}")
    store, entries = _plan(dag, cfg, only, start, force)
    for leftover in store.remove_stale_temporaries():
        console.print(f"removed abandoned partial output {leftover.name}")
    todo = [e for e in entries if e.action == "run"]
    try:
        _execute(dag, cfg, store, entries, local=local or not todo)
    except StageFailed as exc:
        console.print(f"[red]error:[/red] {exc}", highlight=False)
        console.print("(outputs of the stages before it are kept; fix and run again)")
        raise typer.Exit(1) from None
    if dag.report is not None:
        report = dag.report(store, entries, cfg)
        if report is not None:
            console.print(f"report: {report}")
    console.print(
        f"{pipeline}: {len(todo)} stage(s) ran, {len(entries) - len(todo)} cached/skipped, "
        f"{time.perf_counter() - t0:.1f} s; store {store.root}"
    )


def _execute(
    dag: Pipeline, cfg: BaseModel, store: StageStore, entries: list[PlanEntry], local: bool
) -> None:
    """Run the plan here (``local``) or as a Prefect flow, logging one line per stage."""
    from physanim.pipeline import execute_plan_locally
    from physanim.pipeline.progress import rich_progress

    if local:
        with rich_progress(console) as progress:
            execute_plan_locally(dag, cfg, entries, progress, on_result=_log_result)
    else:
        from flows.prefect_env import configure

        configure(cfg.dataset.run_dir)  # type: ignore[attr-defined]
        from flows.pipeline_flow import pipeline_flow

        for e in entries:
            if e.action == "cached":
                store.set_latest(e.stage, e.key)
                _log_result(StageResult(e.stage, e.key, "cached", 0.0, {}))
        with rich_progress(console) as progress:
            named = pipeline_flow.with_options(name=f"physanim-{dag.name}")
            for r in named(dag, cfg, entries, progress):
                _log_result(r)


@app.command()
def status(
    pipeline: PipelineOpt = "face",
    config: ConfigOpt = None,
    set_: SetOpt = None,
    dataset: DatasetOpt = None,
    only: OnlyOpt = None,
    start: FromOpt = None,
    force: ForceOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output")] = False,
) -> None:
    """Dry run: for each stage, cached or will-run, and why."""
    dag = _pipeline(pipeline)
    cfg = load(dag, config, set_, dataset)
    _, entries = _plan(dag, cfg, only, start, force)
    if as_json:
        rows = [
            {"stage": e.stage, "key": e.key, "action": e.action, "why": e.reason} for e in entries
        ]
        print(json.dumps(rows, indent=2))
    else:
        Console().print(_plan_table(entries))


@app.command()
def dag(
    pipeline: PipelineOpt = "face",
    fmt: Annotated[str, typer.Option("--format", "-f", help="text, mermaid or dot")] = "text",
    output: Annotated[Path | None, typer.Option("--output", "-o", help="write to file")] = None,
) -> None:
    """Print the DAG (text), or write it as Mermaid or Graphviz text."""
    d = _pipeline(pipeline)
    if fmt == "mermaid":
        text = d.mermaid()
    elif fmt == "dot":
        text = d.dot()
    elif fmt == "text":
        text = "".join(
            f"{s.name} (v{s.version})"
            + (f" <- {', '.join(s.upstream)}" if s.upstream else "")
            + (f": {s.doc}" if s.doc else "")
            + "\n"
            for s in d.stages
        )
    else:
        raise typer.BadParameter(f"--format must be text, mermaid or dot, not {fmt!r}")
    if output:
        output.write_text(text)
        console.print(f"wrote {output}")
    else:
        print(text, end="")


@app.command()
def show(
    stage: Annotated[str, typer.Argument(help="stage name")],
    key: Annotated[str | None, typer.Option(help="output key (default: latest)")] = None,
    pipeline: PipelineOpt = "face",
    config: ConfigOpt = None,
    set_: SetOpt = None,
    dataset: DatasetOpt = None,
) -> None:
    """Provenance of a stage's latest (or given) output, and the arrays it holds."""
    d = _pipeline(pipeline)
    d.stage(stage)
    cfg = load(d, config, set_, dataset)
    store = StageStore(cfg.dataset.store_path)  # type: ignore[attr-defined]
    if key is not None:
        matches = [k for k in store.keys(stage) if k.startswith(key)]
        if len(matches) != 1:
            console.print(f"[red]error:[/red] key prefix {key!r} matches {len(matches)} outputs")
            raise typer.Exit(2)
        key = matches[0]
    try:
        group = store.open(stage, key)
    except StageOutputMissing as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(1) from None
    info = dict(group.attrs)
    info["arrays"] = {
        name: f"{a.shape} {a.dtype}" for name, a in sorted(group.arrays(), key=lambda x: x[0])
    }
    info["variants"] = store.keys(stage)
    print(json.dumps(info, indent=2, default=str))


@app.command()
def clean(
    pipeline: PipelineOpt = "face",
    config: ConfigOpt = None,
    set_: SetOpt = None,
    dataset: DatasetOpt = None,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="list only")] = False,
) -> None:
    """Remove outputs that neither this config nor any stage's latest pointer reaches."""
    d = _pipeline(pipeline)
    cfg = load(d, config, set_, dataset)
    store, entries = _plan(d, cfg, None, None, None)
    keep = {(e.stage, e.key) for e in entries}
    doomed = store.unreachable(keep)
    for stage, key in doomed:
        print(f"{'would remove' if dry_run else 'removing'} {stage}/{key[:12]}")
        if not dry_run:
            store.remove(stage, key)
    stale = store.stale_temporaries()
    for p in stale:
        print(f"{'would remove' if dry_run else 'removing'} partial output {p.name}")
    if not dry_run:
        store.remove_stale_temporaries()
    if not doomed and not stale:
        print("nothing to clean")


@app.command()
def demo(
    config: ConfigOpt = None,
    set_: SetOpt = None,
    out: Annotated[Path | None, typer.Option(help="directory (default data/demo)")] = None,
    force: Annotated[bool, typer.Option("--force", help="regenerate if present")] = False,
) -> None:
    """Generate the demo dataset (virtual actor from a real scan, bag, RGBD, stereo, truth)."""
    from physanim.capture.demo import generate_demo
    from physanim.pipeline.progress import rich_progress

    cfg = load(_pipeline("face"), config, set_, None)
    target = out or cfg.dataset.path  # type: ignore[attr-defined]
    if target.exists() and not force:
        console.print(f"{target} exists (use --force to regenerate)")
        raise typer.Exit(0)
    with rich_progress(console) as progress:
        made = generate_demo(target, params=cfg.demo, progress=progress("demo dataset"))  # type: ignore[attr-defined]
    console.print(f"generated {made}")


@app.command()
def check(
    dataset: Annotated[str, typer.Argument(help="dataset name (data/<name>) or directory")],
    config: ConfigOpt = None,
    set_: SetOpt = None,
) -> None:
    """Read a dataset's recording and print what it holds, or each problem and its fix."""
    from physanim.capture.check import check_dataset
    from physanim.pipeline.progress import rich_progress

    cfg = load(_pipeline("face"), config, set_, dataset)
    path, track = cfg.dataset.path, cfg.track  # type: ignore[attr-defined]
    with rich_progress(console) as progress:
        report = check_dataset(
            path,
            cfg.ingest,
            track,
            path / track.template,
            progress("reading " + str(path)),  # type: ignore[attr-defined]
        )
    print(f"{path}:")
    for line in report.lines():
        print(line)
    raise typer.Exit(0 if report.ok else 1)


@app.command()
def sweep(
    file: Annotated[Path, typer.Argument(help="sweep YAML, e.g. configs/sweeps/models.yaml")],
    dask_address: Annotated[
        str | None, typer.Option(help="existing Dask scheduler, e.g. tcp://host:8786")
    ] = None,
    workers: Annotated[int, typer.Option(min=1, help="local Dask workers")] = 2,
    serial: Annotated[bool, typer.Option(help="no Dask: one job after another here")] = False,
) -> None:
    """Run a parameter sweep; stages shared between variants are computed once."""
    from physanim.pipeline.sweep import load_sweep

    try:
        spec, variants = load_sweep(file)
        pipeline = _pipeline(spec.pipeline)
        cfg = load(
            pipeline, list(map(Path, variants[0].configs)), list(variants[0].overrides), None
        )
    except ConfigError as exc:
        console.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    from flows.prefect_env import configure

    configure(cfg.dataset.run_dir)  # type: ignore[attr-defined]
    from flows.sweep import run_sweep

    outcome = run_sweep(file, dask_address=dask_address, workers=workers, serial=serial)
    for r in outcome.results:
        _log_result(r)
    table = Table(
        title=f"sweep {file.name}: {len(outcome.results)} stage run(s), {outcome.seconds:.1f} s"
    )
    stages = [s.name for s in pipeline.stages]
    for col in ("variant", *stages):
        table.add_column(col)
    for name, keys in outcome.variants.items():
        table.add_row(name, *(keys[s][:8] for s in stages))
    Console().print(table)
    console.print(f"summary: {outcome.summary_path}")
    console.print(f"report: {outcome.report_path}")


@app.command()
def serve(
    datasets: Annotated[Path, typer.Argument(help="folder whose sub-directories are datasets")],
    pipeline: PipelineOpt = "face",
    config: ConfigOpt = None,
    interval: Annotated[float | None, typer.Option(help="seconds between scheduled runs")] = None,
    cron: Annotated[str | None, typer.Option(help='cron schedule, e.g. "0 2 * * *"')] = None,
) -> None:
    """Serve a scheduled batch deployment: run the pipeline on new or changed datasets."""
    if (interval is None) == (cron is None):
        raise typer.BadParameter("give exactly one of --interval or --cron")
    if not datasets.is_dir():
        raise typer.BadParameter(f"{datasets} is not a directory")
    _pipeline(pipeline)
    from flows.prefect_env import configure, prefect_server

    home = configure(datasets / ".physanim")
    args = [sys.executable, "-m", "flows.schedule", str(datasets.resolve()), pipeline]
    args += ["--interval", str(interval)] if interval is not None else ["--cron", str(cron)]
    args += [str(Path(c).resolve()) for c in config or []]
    with prefect_server(home) as (url, started):
        console.print(f"{'started' if started else 'using'} Prefect server {url}")
        # The deployment is served by a child process: Prefect's runner stops cleanly on
        # SIGINT, so SIGINT/SIGTERM here are forwarded to it as SIGINT; then the server stops.
        child = subprocess.Popen(args, env={**os.environ, "PREFECT_API_URL": url})

        def forward(_signum: int, _frame: object) -> None:
            child.send_signal(signal.SIGINT)

        signal.signal(signal.SIGTERM, forward)
        signal.signal(signal.SIGINT, forward)
        rc = child.wait()
    console.print(f"stopped (server {'stopped' if started else 'left running'})")
    raise typer.Exit(0 if rc in (0, -signal.SIGINT, 130) else rc)


def main() -> None:
    """Console-script entry point."""
    sys.exit(app())
