"""Parameter sweeps over datasets and variants, on Dask through Prefect (prefect-dask).

Every distinct (store, stage, key) of the sweep is one Prefect task; tasks wait for their
upstream tasks, so stages shared by several variants run once and variants fan out in parallel
on the Dask workers.  Import only after ``prefect_env.configure``.
"""

from __future__ import annotations

import json
import os
import socket
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import dask
from distributed import Client, LocalCluster
from prefect import flow, task
from prefect.cache_policies import NONE
from prefect_dask import DaskTaskRunner

from flows.dags import get_pipeline
from physanim.pipeline import Pipeline, StageFailed, StageResult, execute_stage, record_run
from physanim.pipeline.sweep import Job, SweepPlan, blocked, plan_sweep, variant_errors
from physanim.render.sweep_report import SweepVariant, write_sweep_report
from physanim.store import StageStore


@dataclass(frozen=True)
class SweepOutcome:
    """What a sweep did: per-variant stage keys, the jobs that ran (or were found cached),
    the variants that failed (name -> error), wall time (s), summary file (JSON) and report
    (HTML)."""

    variants: dict[str, dict[str, str]]
    results: list[StageResult]
    errors: dict[str, str]
    seconds: float
    summary_path: Path
    report_path: Path


#: What became of one job: its result, its error (text), or None (an upstream job failed)
Outcome = StageResult | str | None


@task(cache_policy=NONE, persist_result=False)
def sweep_stage(pipeline: Pipeline, config: dict[str, Any], job: Job, cwd: str) -> StageResult:
    """Run one distinct stage execution of the sweep on a worker, in the sweep's working
    directory (relative paths in configs mean the same on every worker)."""
    if os.getcwd() != cwd:
        try:
            os.chdir(cwd)
        except OSError as exc:
            raise RuntimeError(
                f"worker {socket.gethostname()}:{os.getpid()} cannot enter the sweep's working "
                f"directory {cwd} ({exc.strerror}): the workers must see the same files at the "
                "same paths (this machine, or a shared file system)"
            ) from None
    return execute_stage(pipeline, config, job.entry)


def _error(exc: BaseException) -> str:
    """One line for a failed job (StageFailed already names the stage)."""
    return str(exc) if isinstance(exc, StageFailed) else f"{type(exc).__name__}: {exc}"


@flow(name="physanim-sweep", persist_result=False, validate_parameters=False)
def sweep_flow(
    pipeline: Pipeline, configs: dict[str, dict[str, Any]], jobs: list[Job], cwd: str
) -> list[Outcome]:
    """Submit every job, each waiting for the jobs of its upstream stages; one outcome per
    job. A failed job fails only the jobs downstream of it: the others run to the end."""
    futures: dict[tuple[str, str, str], Any] = {}
    for job in jobs:
        named = sweep_stage.with_options(
            name=job.entry.stage, task_run_name=f"{job.entry.stage}-{job.entry.key[:8]}"
        )
        deps = [futures[d] for d in job.deps if d in futures]
        futures[job.ident] = named.submit(pipeline, configs[job.variant], job, cwd, wait_for=deps)
    outcomes: dict[tuple[str, str, str], Outcome] = {}
    for job in jobs:  # deps come first
        futures[job.ident].wait()
        if blocked(job, outcomes):
            outcomes[job.ident] = None
            continue
        try:
            outcomes[job.ident] = futures[job.ident].result()
        except Exception as exc:  # the stage's error, or a worker lost too often (KilledWorker)
            outcomes[job.ident] = _error(exc)
    return list(outcomes.values())


def run_serially(pipeline: Pipeline, configs: dict[str, Any], jobs: list[Job]) -> list[Outcome]:
    """The jobs one after another in this process; a failed job skips its downstream only."""
    outcomes: dict[tuple[str, str, str], Outcome] = {}
    for job in jobs:
        if blocked(job, outcomes):
            outcomes[job.ident] = None
            continue
        try:
            outcomes[job.ident] = execute_stage(pipeline, configs[job.variant], job.entry)
        except Exception as exc:
            outcomes[job.ident] = _error(exc)
    return list(outcomes.values())


#: Dask's nannies start local workers with MALLOC_TRIM_THRESHOLD_=65536, which hands every
#: large numpy temporary back to the OS and faults it in again: numpy-heavy stages ran up to
#: 1.6x slower in a worker than in this process (evaluate 8.4-9.9 s vs 5.4-6.2 s); keep glibc's
#: default. (Workers of an existing cluster keep whatever their own config says.)
NO_MALLOC_TRIM = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}

#: Thread-pool sizes of the numerical libraries, read by each worker process at start
THREAD_ENV = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def worker_thread_env(
    workers: int, cores: int | None = None, per_worker: int | None = None
) -> dict[str, str]:
    """Environment for local Dask workers: the machine's cores shared out between them
    (or ``per_worker`` threads each).

    Each worker would otherwise size its numba (FEM solve), OpenMP and BLAS pools to every
    core, and workers x cores spinning threads on the same cores ran slower than one process.
    """
    per_worker = per_worker or max(1, (cores or os.cpu_count() or 1) // max(1, workers))
    return {name: str(per_worker) for name in THREAD_ENV}


def _prefect_api() -> tuple[str, bool]:
    """The URL of the Prefect API that the sweep's flow and its workers report to, and
    whether it is this process's temporary server (started here; it listens on 127.0.0.1).

    The flow runs with this URL in its settings, which Prefect hands to every task on a
    worker; a worker without it starts a temporary server of its own (about 15 s of CPU,
    measured here) and keeps it until the worker exits.
    """
    from prefect.settings import PREFECT_API_URL

    if PREFECT_API_URL.value():
        return str(PREFECT_API_URL.value()), False
    from prefect.server.api.server import SubprocessASGIServer

    server = SubprocessASGIServer()  # the instance a flow run in this process would start
    server.start()
    return server.api_url, True


def _connect(address: str, timeout_s: float = 10.0) -> Client:
    """A client of the scheduler at ``address``; a one-line error when none answers."""
    try:
        return Client(address, timeout=f"{timeout_s}s")
    except OSError as exc:
        raise ValueError(
            f"--dask-address {address}: no Dask scheduler answers there ({exc}); start one "
            "with `dask scheduler` or check the address"
        ) from None


def _check_workers(client: Client, address: str, local_api: bool, timeout_s: float = 60.0) -> None:
    """Refuse, in one line, a cluster with no worker within ``timeout_s``, and workers on
    other machines when the Prefect API is this process's temporary server (they cannot
    reach it)."""
    try:
        client.wait_for_workers(1, timeout=timeout_s)
    except TimeoutError:
        raise ValueError(
            f"--dask-address {address}: the scheduler has no workers; start them with "
            f"`dask worker {address} --nthreads 1 --preload flows.worker_preload`"
        ) from None
    hosts = set(client.run(socket.gethostname).values())
    if local_api and hosts - {socket.gethostname()}:
        raise ValueError(
            f"--dask-address {address}: workers on {', '.join(sorted(hosts))} cannot reach this "
            "process's temporary Prefect server on 127.0.0.1; start a server they can reach "
            "(`prefect server start --host 0.0.0.0`) and set PREFECT_API_URL to it"
        )


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class LocalDask:
    """A local Dask cluster for one sweep, started in a background thread (so that it comes
    up while Prefect's server does) and closed in one (while the report is written)."""

    def __init__(self, workers: int, scratch: Path, env: dict[str, str]) -> None:
        self.address = f"tcp://127.0.0.1:{_free_port()}"
        self._cluster: LocalCluster | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(
            target=self._start, args=(workers, scratch, env), name="physanim-dask-start"
        )
        self._thread.start()

    def _start(self, workers: int, scratch: Path, env: dict[str, str]) -> None:
        try:
            with dask.config.set(NO_MALLOC_TRIM):
                self._cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    scheduler_port=int(self.address.rsplit(":", 1)[1]),
                    dashboard_address=None,
                    local_directory=str(scratch),
                    preload=["flows.worker_preload"],
                    env=env,
                )
        except BaseException as exc:  # re-raised in the caller's thread by wait()
            self._error = exc

    def wait(self) -> str:
        """The scheduler address once every worker is up; raises if the cluster failed."""
        self._thread.join()
        if self._error is not None:
            raise RuntimeError(f"local Dask cluster did not start: {self._error}") from self._error
        return self.address

    def close_in_background(self) -> threading.Thread:
        """Start closing the cluster; join the returned thread before exiting."""
        self._thread.join()
        thread = threading.Thread(target=self._close, name="physanim-dask-close")
        thread.start()
        return thread

    def _close(self) -> None:
        if self._cluster is not None:
            self._cluster.close()


def run_sweep(
    sweep: Path | SweepPlan,
    *,
    dask_address: str | None = None,
    workers: int = 2,
    serial: bool = False,
    worker_threads: int | None = None,
) -> SweepOutcome:
    """Run a sweep (a file, or its plan); ``serial`` runs the jobs one by one in this process
    (reference timing). Local workers get ``worker_threads`` numerical threads each (default:
    the cores shared out). A variant whose stage fails is reported in ``errors``; the others
    run to the end."""
    from prefect.settings import PREFECT_API_URL, temporary_settings

    plan = sweep if isinstance(sweep, SweepPlan) else plan_sweep(sweep, get_pipeline)
    t0 = time.perf_counter()
    closing = None
    if serial:
        outcomes = run_serially(plan.pipeline, plan.configs, plan.jobs)
    elif plan.jobs:
        scratch = Path(plan.run_dir).resolve() / "dask"
        scratch.mkdir(parents=True, exist_ok=True)
        os.environ.setdefault("DASK_TEMPORARY_DIRECTORY", str(scratch))
        env = worker_thread_env(workers, per_worker=worker_threads)
        local = None if dask_address else LocalDask(workers, scratch, env)
        client = _connect(dask_address) if dask_address else None
        try:  # the cluster comes up while Prefect's server does
            url, local_api = _prefect_api()
            if client is not None:
                with client:
                    _check_workers(client, dask_address, local_api)
            else:
                dask_address = local.wait()
            runner = DaskTaskRunner(address=dask_address)
            dumped = {k: c.model_dump(mode="json") for k, c in plan.configs.items()}
            with temporary_settings({PREFECT_API_URL: url}):  # handed to every task
                flow_run = sweep_flow.with_options(task_runner=runner)
                outcomes = flow_run(plan.pipeline, dumped, plan.jobs, os.getcwd())
        except BaseException:
            if local is not None:
                local.close_in_background().join()
            raise
        if local is not None:
            closing = local.close_in_background()
    else:
        outcomes = []
    seconds = time.perf_counter() - t0

    results = [o for o in outcomes if isinstance(o, StageResult)]
    failed = {j.ident: o for j, o in zip(plan.jobs, outcomes, strict=True) if isinstance(o, str)}
    errors = variant_errors(plan, failed)
    try:
        summary, report = _record_sweep(plan, results, errors, seconds)
    finally:
        if closing is not None:
            closing.join()
    return SweepOutcome(plan.keys, results, errors, seconds, summary, report)


def _record_sweep(
    plan: SweepPlan, results: list[StageResult], errors: dict[str, str], seconds: float
) -> tuple[Path, Path]:
    """Remove what killed workers left half-written, record each variant as a run of its
    store (not the latest), write the sweep's summary.json and report (HTML); returns their
    paths."""
    for root in set(plan.stores.values()):
        StageStore(root).remove_stale_temporaries()
    report_variants = []
    for v in plan.variants:
        store = StageStore(plan.stores[v.name])
        done = {stage: key for stage, key in plan.keys[v.name].items() if store.has(stage, key)}
        info = {"sweep": str(plan.path), "variant": v.name, "configs": list(v.configs)}
        record_run(
            store, plan.pipeline, done, {**info, "overrides": list(v.overrides)}, latest=False
        )
        report_variants.append(
            SweepVariant(
                name=v.name,
                dataset=v.dataset,
                configs=v.configs,
                overrides=v.overrides,
                keys=plan.keys[v.name],
                summaries={s: store.provenance(s, k).get("summary", {}) for s, k in done.items()},
                files={s: store.files(s, k) for s, k in done.items()},
                error=errors.get(v.name, ""),
            )
        )
    out = plan.run_dir / "sweeps" / plan.path.stem
    out.mkdir(parents=True, exist_ok=True)
    record = {
        "sweep": str(plan.path),
        "seconds": seconds,
        "variants": [
            {
                "variant": v.name,
                "dataset": v.dataset,
                "configs": list(v.configs),
                "overrides": list(v.overrides),
                "keys": dict(v.keys),
                "summaries": dict(v.summaries),
                "error": v.error or None,
            }
            for v in report_variants
        ],
        "runs": [{k: x for k, x in asdict(r).items() if k != "summary"} for r in results],
    }
    partial = out / "summary.json.partial"  # renamed into place: never half-written
    partial.write_text(json.dumps(record, indent=2, default=str))
    partial.replace(out / "summary.json")
    report = write_sweep_report(
        out,
        title=f"Sweep {plan.path.stem}",
        variants=report_variants,
        results=results,
        seconds=seconds,
        subtitle=f"{plan.path}: {plan.pipeline.name} pipeline,",
    )
    return out / "summary.json", report
