"""The ``physanim`` command line: run, status, verify, dag, show, clean, demo, sweep, serve.

The CLI is the application's entry point, above ``flows/``: it loads the DAG declarations from
``flows.dags`` and runs plans through an executor (``physanim.pipeline``'s local one, or
``flows.executors``' Prefect and Dask ones, imported lazily, so ``status``, ``dag``, ``show``
and ``clean`` never need Prefect).  Errors are one line; ``--debug`` anywhere on the command
line (or PHYSANIM_DEBUG=1) shows their tracebacks.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from cli.options import (
    ConfigOpt,
    PipelineOpt,
    SetOpt,
    Target,
    console,
    fail,
    get_pipeline,
    load,
    with_target,
)
from physanim.config import ConfigError
from physanim.pipeline import (
    Executor,
    LocalExecutor,
    Pipeline,
    PipelineConfig,
    PlanEntry,
    ProgressFactory,
    StageFailed,
    StageResult,
    make_plan,
    run_plan,
)
from physanim.pipeline.progress import rich_progress
from physanim.store import StageOutputMissing, StageStore
from physanim.store.stage_store import QUARANTINE

app = typer.Typer(
    add_completion=False, no_args_is_help=True, help=__doc__, pretty_exceptions_enable=False
)
#: set by ``main`` from --debug / PHYSANIM_DEBUG: errors show their tracebacks
DEBUG = False

OnlyOpt = Annotated[str | None, typer.Option("--only", help="run just this stage")]
FromOpt = Annotated[str | None, typer.Option("--from", help="run this stage and its downstream")]
ForceOpt = Annotated[
    list[str] | None, typer.Option("--force", help="recompute this stage even if cached")
]


def _stage(pipeline: Pipeline, name: str) -> None:
    try:
        pipeline.stage(name)
    except ValueError as exc:
        raise fail(str(exc)) from None


def _plan(
    target: Target,
    only: str | None = None,
    start: str | None = None,
    force: list[str] | None = None,
    *,
    create: bool = True,
    checksums: bool = False,
) -> tuple[StageStore, list[PlanEntry]]:
    """The target's store and the plan of a run of it (``create``: as for Target.store)."""
    store = target.store(create=create)
    try:
        entries = make_plan(
            target.pipeline,
            target.config,
            store,
            only=only,
            start=start,
            force=force or (),
            checksums=checksums,
        )
    except ValueError as exc:
        raise fail(str(exc)) from None
    return store, entries


def _action(e: PlanEntry) -> str:
    """What the plan does with a stage, as ``status`` says it."""
    if e.action == "run":
        return "damaged, will run" if e.damage else "will run"
    return f"{e.action} (damaged)" if e.damage else e.action


def _plan_table(entries: list[PlanEntry]) -> Table:
    table = Table(title="plan")
    for col in ("stage", "key", "action", "why"):
        table.add_column(col)
    colour = {"cached": "green", "run": "yellow", "skip": "dim"}
    for e in entries:
        colour_of = "red" if e.damage else colour[e.action]
        table.add_row(e.stage, e.key[:12], f"[{colour_of}]{_action(e)}", escape(e.reason))
    return table


def _log_result(r: StageResult) -> None:
    if r.action == "cached":
        console.print(f"[green]{r.stage}[/green]: cached ({r.key[:12]})")
    else:
        console.print(f"[yellow]{r.stage}[/yellow]: ran in {r.seconds:.2f} s ({r.key[:12]})")
        for warning in r.summary.get("warnings", ()):
            console.print(f"[yellow]warning:[/yellow] {warning}", highlight=False)


@app.command()
@with_target
def run(
    target: Target,
    only: OnlyOpt = None,
    start: FromOpt = None,
    force: ForceOpt = None,
    local: Annotated[
        bool, typer.Option("--local", help="run stages in this process without Prefect")
    ] = False,
    verify: Annotated[
        bool, typer.Option("--verify", help="check cached outputs' checksums, recompute damage")
    ] = False,
) -> None:
    """Run the DAG (or part of it); cached stages are reused, damaged ones recomputed."""
    t0 = time.perf_counter()
    dag, cfg = target.pipeline, target.config
    _tidy_up()
    _prepare(dag, cfg, None if local else partial(_start_prefect, cfg))
    store, entries = _plan(target, only, start, force, checksums=verify)
    for leftover in store.remove_stale_temporaries():
        console.print(f"removed abandoned partial output {leftover.name}")
    _quarantine(store, entries)
    todo = [e for e in entries if e.action == "run"]
    info = {"configs": [str(c) for c in target.configs], "overrides": target.overrides}
    try:
        with rich_progress(console) as progress:
            executor = _executor(dag, cfg, progress, local=local or not todo)
            run_plan(executor, dag, cfg, entries, on_result=_log_result, info=info)
    except StageFailed as exc:
        if DEBUG:
            raise
        cause = exc.__cause__
        where = str(store.root)
        text = (
            f"stage '{exc.stage}' failed: {_describe(cause, where)}" if _is_io(cause) else str(exc)
        )
        fail(text)
        console.print("(outputs of the stages before it are kept; fix and run again)")
        raise typer.Exit(1) from None
    if dag.report is not None:
        report = dag.report(store, entries, cfg)
        if report is not None:
            console.print(f"report: {report}")
    console.print(
        f"{dag.name}: {len(todo)} stage(s) ran, {len(entries) - len(todo)} cached/skipped, "
        f"{time.perf_counter() - t0:.1f} s; store {store.root}"
    )


def _executor(
    dag: Pipeline, cfg: PipelineConfig, progress: ProgressFactory, *, local: bool
) -> Executor:
    """This process's executor (``local``: no Prefect is imported), else a Prefect flow
    reporting to the run directory's shared Prefect server."""
    if local:
        return LocalExecutor(progress)
    from flows.prefect_env import configure

    home = configure(cfg.dataset.run_dir)  # (before Prefect loads)
    from flows.executors import PrefectExecutor

    return PrefectExecutor(home, name=f"physanim-{dag.name}", progress=progress)


def _start_prefect(cfg: PipelineConfig) -> None:
    """Begin starting the run directory's shared Prefect server (it takes 10-25 s; the
    executor waits for it later)."""
    from flows.prefect_env import configure, start_shared_server

    start_shared_server(configure(cfg.dataset.run_dir))


def _prepare(
    dag: Pipeline, cfg: PipelineConfig, starting: Callable[[], None] | None = None
) -> None:
    """Make what the pipeline needs before it can be planned (the demo dataset), saying so;
    ``starting()`` runs first when there is something to make."""
    if dag.prepare is not None:
        t0 = time.perf_counter()
        with rich_progress(console) as progress:
            made = dag.prepare(cfg, progress, starting)
        if made:
            console.print(f"generated {made} in {time.perf_counter() - t0:.1f} s")


def _quarantine(store: StageStore, entries: list[PlanEntry]) -> None:
    """Move the damaged outputs that the plan recomputes out of the way, saying where."""
    for e in entries:
        if e.damage and e.action == "run":
            moved = store.quarantine(e.stage, e.key, e.damage)
            console.print(
                f"[red]{e.stage}/{e.key[:12]} is damaged[/red] ({escape(e.damage)}): moved to "
                f"{escape(str(moved))}; recomputing it",
                highlight=False,
            )


def _tidy_up() -> None:
    """Stop processes and remove temporary folders that killed physanim runs left behind;
    mark the processes this one starts as its own (so a later run can do the same for it)."""
    from physanim.processes import mark_children, remove_stale_temp_dirs, stop_orphans

    mark_children()
    for line in stop_orphans():
        console.print(line, highlight=False)
    for folder in remove_stale_temp_dirs():
        console.print(f"removed {folder}, left behind by a killed physanim", highlight=False)


@app.command()
@with_target
def status(
    target: Target,
    only: OnlyOpt = None,
    start: FromOpt = None,
    force: ForceOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable output")] = False,
    verify: Annotated[
        bool, typer.Option("--verify", help="also check the checksums of cached outputs")
    ] = False,
) -> None:
    """Dry run: for each stage, cached, will run or damaged, and why (writes nothing)."""
    data = target.config.dataset.path
    if not data.exists():
        console.print(f"note: dataset directory {data} does not exist", highlight=False)
    store, entries = _plan(target, only, start, force, create=False, checksums=verify)
    if as_json:
        rows = [
            {"stage": e.stage, "key": e.key, "action": e.action, "why": e.reason,
             "damaged": e.damage}
            for e in entries
        ]  # fmt: skip
        print(json.dumps(rows, indent=2))
    else:
        Console().print(_plan_table(entries))
        for e in entries:  # in full: the table's column may cut a long path short
            if e.damage:
                print(_damage_line(store, e.stage, e.key, e.damage))
        for meta in store.damaged_groups():
            print(f"damaged: group metadata {meta} is unreadable; `physanim verify` rewrites it")


def _damage_line(store: StageStore, stage: str, key: str, problem: str) -> str:
    """``damaged: stage/key (its path): problem``: the damaged file's path, or the output's
    with the file named in ``problem``."""
    where = store.root / stage / key
    at = "" if str(where) in problem else f" ({where})"
    return f"damaged: {stage}/{key[:12]}{at}: {problem}"


@app.command()
@with_target
def verify(target: Target) -> None:
    """Check every output of the store against its manifest (files, sizes, checksums);
    remove the partial outputs that killed or failed runs left in its .tmp/."""
    store = target.store(create=False)
    try:  # what killed or failed writers left in .tmp/ (a read-only store keeps it)
        removed = store.remove_stale_temporaries()
    except OSError:
        removed = []
    for leftover in removed:
        print(f"removed abandoned partial output {leftover.name}")
    try:  # the store's and stages' empty groups: rewriting them loses nothing
        repaired = store.repair_groups()
    except OSError:
        repaired = []
    for meta in repaired:
        print(f"rewrote unreadable group metadata {meta}")
    checked = damaged = 0
    for meta in store.damaged_groups():  # (a read-only store)
        damaged += 1
        print(f"damaged: group metadata {meta} is unreadable")
    for stage in store.stages():
        for key in store.all_keys(stage):
            checked += 1
            problem = store.damage(stage, key, checksums=True)
            if problem is not None:
                damaged += 1
                print(_damage_line(store, stage, key, problem))
    line = f"{checked} output(s) checked in {store.root}, {damaged} damaged"
    quarantined = [p for p in store.quarantined() if p.is_dir()]
    if quarantined:
        line += f"; {len(quarantined)} moved aside earlier to {store.root / QUARANTINE}"
    print(line)
    if damaged:
        print("`physanim run --verify` moves damaged outputs aside and recomputes those it needs")
        raise typer.Exit(1)


#: ``physanim dag --format``: name -> the text of a pipeline in that format
DAG_FORMATS: dict[str, Callable[[Pipeline], str]] = {
    "text": Pipeline.text,
    "mermaid": Pipeline.mermaid,
    "dot": Pipeline.dot,
}


@app.command()
def dag(
    pipeline: PipelineOpt = "face",
    fmt: Annotated[str, typer.Option("--format", "-f", help="text, mermaid or dot")] = "text",
    output: Annotated[Path | None, typer.Option("--output", "-o", help="write to file")] = None,
) -> None:
    """Print the DAG (text), or write it as Mermaid or Graphviz text."""
    d = get_pipeline(pipeline)
    if fmt not in DAG_FORMATS:
        raise typer.BadParameter(f"--format must be {', '.join(DAG_FORMATS)}, not {fmt!r}")
    text = DAG_FORMATS[fmt](d)
    if output:
        output.write_text(text)
        console.print(f"wrote {output}")
    else:
        print(text, end="")


@app.command()
@with_target
def show(
    stage: Annotated[str, typer.Argument(help="stage name")],
    target: Target,
    key: Annotated[
        str | None,
        typer.Option(
            help="output key prefix (default: the -c / --set configuration's, else latest)"
        ),
    ] = None,
) -> None:
    """Provenance of a stage's output, the arrays it holds and where its plain files are
    (``files.folder``: videos, figures, exported meshes): the output of the configuration that
    ``-c`` / ``--set`` give, else of the latest run, or the one ``--key`` names."""
    _stage(target.pipeline, stage)
    store = target.store(create=False)
    if key is not None:
        matches = [k for k in store.all_keys(stage) if k.startswith(key)]
        if len(matches) != 1:
            raise fail(f"key prefix {key!r} matches {len(matches)} outputs of {stage}")
        key = matches[0]
    elif target.chosen:
        _, entries = _plan(target, create=False)
        key = next(e.key for e in entries if e.stage == stage)
        if key not in store.all_keys(stage):
            raise fail(
                f"{stage} has no output for this configuration yet (key {key[:12]}): run "
                "`physanim run` with the same -c / --set first, or drop them to see the latest",
                1,
            )
    try:
        group = store.open(stage, key)
    except StageOutputMissing as exc:
        raise fail(str(exc), 1) from None
    info = dict(group.attrs)
    manifest = info.pop("manifest", {})
    info["files"] = {"count": len(manifest), "bytes": sum(size for size, _ in manifest.values())}
    folder = Path(group.store.root) / group.path / "files"  # plain files beside the arrays
    if folder.is_dir():
        info["files"]["folder"] = str(folder.resolve())
        info["files"]["plain"] = {
            p.relative_to(folder).as_posix(): p.stat().st_size
            for p in sorted(folder.rglob("*"))
            if p.is_file()
        }
    with warnings.catch_warnings():  # plain files/ beside the arrays are not Zarr nodes
        warnings.simplefilter("ignore")
        arrays = sorted(group.arrays(), key=lambda x: x[0])
    info["arrays"] = {name: f"{a.shape} {a.dtype}" for name, a in arrays}
    info["variants"] = store.keys(stage)
    print(json.dumps(info, indent=2, default=str))


@app.command()
@with_target
def clean(
    target: Target,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="list only")] = False,
) -> None:
    """Remove outputs that neither this config, the latest run nor any complete run (the
    report's variants) uses, with everything they were computed from kept; also damaged and
    quarantined outputs and abandoned partial ones."""
    d = target.pipeline
    store, entries = _plan(target, create=False)
    store.adopt_unrecorded(d.name, [s.name for s in d.stages])  # a store from before runs
    latest = store.latest_run_name()
    kept_runs = [r for r in store.runs() if r.name == latest or r.info.get("complete")]
    keep = {(e.stage, e.key) for e in entries}
    keep |= {item for r in kept_runs for item in r.keys.items()}
    verb = "would remove" if dry_run else "removing"
    doomed = store.unreachable(keep)
    for stage, key in doomed:
        print(f"{verb} {stage}/{key[:12]}")
        if not dry_run:
            store.remove(stage, key)
    damaged = [(s, k, p) for s in store.stages() for k in store.all_keys(s)
               if (p := store.damage(s, k)) is not None]  # fmt: skip
    for stage, key, problem in damaged:
        print(f"{verb} damaged {stage}/{key[:12]} ({problem})")
        if not dry_run:
            store.remove(stage, key)
    kept_names = {r.name for r in kept_runs}
    runs = [r.name for r in store.runs() if r.name not in kept_names]
    for name in runs:
        print(f"{verb} run manifest {name} (an incomplete run, not the latest)")
        if not dry_run:
            store.remove_run(name)
    stale, quarantined = store.stale_temporaries(), store.quarantined()
    for p in stale:
        print(f"{verb} partial output {p.name}")
    for p in quarantined:
        print(f"{verb} quarantined {p.name}")
    if not dry_run:
        store.remove_stale_temporaries()
        for p in quarantined:
            if p.is_dir():
                shutil.rmtree(p)
            else:
                p.unlink()
    if not (doomed or damaged or runs or stale or quarantined):
        print("nothing to clean")


@app.command()
def demo(
    config: ConfigOpt = None,
    set_: SetOpt = None,
    out: Annotated[Path | None, typer.Option(help="directory (default data/demo)")] = None,
    force: Annotated[bool, typer.Option("--force", help="regenerate if present")] = False,
) -> None:
    """Generate the demo dataset (virtual actor from a real scan, bag, RGBD, stereo, truth);
    a performance library dataset's name (e.g. --set dataset.name=lips-s1-coarse) sets its
    performance, seed, frames and markers."""
    from physanim.capture.demo import generate_demo
    from physanim.capture.library import library_params
    from physanim.capture.params import DemoParams

    cfg = load(get_pipeline("face"), config, set_, None)
    target = out or cfg.dataset.path
    if target.exists() and not force:
        console.print(f"{target} exists (use --force to regenerate)")
        raise typer.Exit(0)
    with rich_progress(console) as progress:
        demo = cfg.section("demo", DemoParams)
        demo = library_params(cfg.dataset.name, demo) or demo
        made = generate_demo(target, params=demo, progress=progress("demo dataset"))
    console.print(f"generated {made}")


@app.command()
def check(
    dataset: Annotated[str, typer.Argument(help="dataset name (data/<name>) or directory")],
    config: ConfigOpt = None,
    set_: SetOpt = None,
) -> None:
    """Read a dataset's recording and print what it holds, or each problem and its fix."""
    from physanim.capture.params import IngestParams
    from physanim.tracking.dataset_check import check_dataset
    from tasks.track import TrackStageParams

    cfg = load(get_pipeline("face"), config, set_, dataset)
    path, track = cfg.dataset.path, cfg.section("track", TrackStageParams)
    with rich_progress(console) as progress:
        report = check_dataset(
            path,
            cfg.section("ingest", IngestParams),
            track,
            path / track.template,
            progress("reading " + str(path)),
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
    from physanim.pipeline.sweep import plan_sweep

    _tidy_up()
    try:  # every variant is valid and planned before anything starts
        plan = plan_sweep(file, get_pipeline, prepare=_prepare)
    except (ConfigError, ValueError) as exc:  # an invalid variant, an unknown pipeline
        raise fail(str(exc)) from None
    for job in plan.jobs:
        _quarantine(StageStore(job.store), [job.entry])
    from flows.prefect_env import configure

    configure(plan.run_dir)  # before Prefect is imported
    from flows.sweep import run_sweep

    try:
        outcome = run_sweep(plan, dask_address=dask_address, workers=workers, serial=serial)
    except ValueError as exc:  # a scheduler that does not answer, workers it cannot serve
        raise fail(str(exc)) from None
    for r in outcome.results:
        _log_result(r)
    table = Table(
        title=f"sweep {file.name}: {len(outcome.results)} stage run(s), {outcome.seconds:.1f} s"
    )
    stages = [s.name for s in plan.pipeline.stages]
    for col in ("variant", *stages):
        table.add_column(col)
    for name, keys in outcome.variants.items():
        table.add_row(name, *(keys[s][:8] for s in stages))
    Console().print(table)
    console.print(f"summary: {outcome.summary_path}")
    console.print(f"report: {outcome.report_path}")
    if outcome.errors:
        for name, error in outcome.errors.items():
            console.print(f"[red]error:[/red] variant {escape(name)!r}: {escape(error)}")
        raise typer.Exit(1)


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
    get_pipeline(pipeline)
    _tidy_up()
    from flows.prefect_env import configure, prefect_server

    home = configure(datasets / ".physanim")
    args = [sys.executable, "-m", "flows.schedule", str(datasets.resolve()), pipeline]
    args += ["--interval", str(interval)] if interval is not None else ["--cron", str(cron)]
    args += [str(Path(c).resolve()) for c in config or []]
    with prefect_server(home) as (url, started):
        console.print(f"{'started' if started else 'using'} Prefect server {url}")
        # The deployment is served by a child process: Prefect's runner stops cleanly on
        # SIGINT, so SIGINT/SIGTERM here are forwarded to it as SIGINT; then the server stops.
        # Its own session holds it and the flow runs it starts, so none outlives the stop.
        child = subprocess.Popen(
            args, env={**os.environ, "PREFECT_API_URL": url}, start_new_session=True
        )
        asked: list[float] = []  # when a stop was asked for

        def forward(_signum: int, _frame: object) -> None:
            asked.append(time.monotonic())
            child.send_signal(signal.SIGINT)

        signal.signal(signal.SIGTERM, forward)
        signal.signal(signal.SIGINT, forward)
        rc = _wait_or_kill(child, asked)
    console.print(f"stopped (server {'stopped' if started else 'left running'})")
    raise typer.Exit(0 if rc in (0, -signal.SIGINT, 130, -signal.SIGKILL) and asked else rc)


#: Seconds ``serve`` gives Prefect's runner to stop after SIGINT before killing it.
SERVE_STOP_GRACE_S = 20.0


def _wait_or_kill(child: subprocess.Popen, asked: list[float]) -> int:
    """The child's exit status; killed when it is still running ``SERVE_STOP_GRACE_S`` after
    the first stop request in ``asked`` (Prefect's runner has hung in its shutdown when the
    server's SQLite database stayed locked). Then whatever is left of the process group it
    leads is killed too: a flow run the runner started and left behind waited for ever on
    the stopped server, holding ``serve``'s output open."""
    while True:
        try:
            rc = child.wait(timeout=1.0)
            break
        except subprocess.TimeoutExpired:
            if asked and time.monotonic() - asked[0] > SERVE_STOP_GRACE_S:
                console.print(
                    f"the scheduler did not stop within {SERVE_STOP_GRACE_S:.0f} s of the "
                    "signal; killed it"
                )
                child.kill()
                rc = child.wait()
                break
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(child.pid, signal.SIGKILL)  # no group of that id: nothing left
    return rc


def _is_io(exc: BaseException | None) -> bool:
    return isinstance(exc, OSError) and exc.errno is not None


def _describe(exc: BaseException | None, where: str = "the store") -> str:
    """One line for an error: what failed, on which file (else ``where``), and what to do."""
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
        return (
            f"no space left writing {exc.filename or where} ({exc.strerror}); the "
            "partial output was discarded, the store is unchanged: free space and run again"
        )
    if isinstance(exc, OSError) and exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return (
            f"cannot write {exc.filename or where} ({exc.strerror}): make the store "
            "writable, or give another dataset directory with --dataset"
        )
    if isinstance(exc, OSError) and exc.errno is not None:
        return f"{exc.filename or 'I/O error'}: {exc.strerror}"
    if isinstance(exc, ConfigError | StageOutputMissing | StageFailed):
        return str(exc)
    return f"{type(exc).__name__}: {exc} (unexpected; --debug shows the traceback)"


def main() -> None:
    """Console-script entry point: errors become one line unless --debug (anywhere) or
    PHYSANIM_DEBUG=1 asks for the traceback."""
    global DEBUG
    DEBUG = "--debug" in sys.argv[1:] or os.environ.get("PHYSANIM_DEBUG", "") not in ("", "0")
    sys.argv = [sys.argv[0], *(a for a in sys.argv[1:] if a != "--debug")]
    try:
        sys.exit(app())
    except KeyboardInterrupt:
        console.print("interrupted")
        sys.exit(130)
    except Exception as exc:
        if DEBUG:
            raise
        fail(_describe(exc))
        sys.exit(1)
