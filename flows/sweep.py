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
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import dask
from distributed import LocalCluster
from prefect import flow, task
from prefect.cache_policies import NONE
from prefect_dask import DaskTaskRunner

from flows.dags import get_pipeline
from physanim.config import ConfigError, load_config
from physanim.pipeline import Pipeline, StageResult, execute_stage, make_plan, record_run
from physanim.pipeline.sweep import Job, Variant, load_sweep, merge_plans
from physanim.render.sweep_report import SweepVariant, write_sweep_report
from physanim.store import StageStore


@dataclass(frozen=True)
class SweepOutcome:
    """What a sweep did: per-variant stage keys, the jobs run, wall time (s), summary file
    (JSON) and report (HTML)."""

    variants: dict[str, dict[str, str]]
    results: list[StageResult]
    seconds: float
    summary_path: Path
    report_path: Path


@task(cache_policy=NONE, persist_result=False)
def sweep_stage(pipeline: Pipeline, config: dict[str, Any], job: Job) -> StageResult:
    """Run one distinct stage execution of the sweep on a worker."""
    return execute_stage(pipeline, config, job.entry)


@flow(name="physanim-sweep", persist_result=False, validate_parameters=False)
def sweep_flow(
    pipeline: Pipeline, configs: dict[str, dict[str, Any]], jobs: list[Job]
) -> list[StageResult]:
    """Submit every job, each waiting for the jobs of its upstream stages."""
    futures: dict[tuple[str, str, str], Any] = {}
    for job in jobs:
        deps = [futures[d] for d in job.deps if d in futures]
        named = sweep_stage.with_options(
            name=job.entry.stage, task_run_name=f"{job.entry.stage}-{job.entry.key[:8]}"
        )
        futures[job.ident] = named.submit(pipeline, configs[job.variant], job, wait_for=deps)
    return [f.result() for f in futures.values()]


def plan_sweep(
    path: Path,
) -> tuple[Pipeline, list[Variant], dict[str, Any], dict[str, dict[str, str]], list[Job]]:
    """Expand a sweep file, validate every variant's config and merge their plans.

    Returns (pipeline, variants, variant -> config, variant -> stage -> key, jobs to run).
    """
    spec, variants = load_sweep(path)
    pipeline = get_pipeline(spec.pipeline)
    configs: dict[str, Any] = {}
    plans = {}
    for v in variants:
        try:
            cfg, _ = load_config(
                pipeline.config_model(), [pipeline.default_config, *v.configs], v.overrides
            )
        except ConfigError as exc:
            raise ConfigError(f"{path}: variant {v.name!r}: {exc}") from None
        store = StageStore(cfg.dataset.store_path)  # type: ignore[attr-defined]
        store.remove_stale_temporaries()
        configs[v.name] = cfg
        plans[v.name] = (str(store.root), make_plan(pipeline, cfg, store))
    keys = {name: {e.stage: e.key for e in plan} for name, (_, plan) in plans.items()}
    return pipeline, variants, configs, keys, merge_plans(plans) if plans else []


#: Dask's nannies start local workers with MALLOC_TRIM_THRESHOLD_=65536, which hands every
#: large numpy temporary back to the OS and faults it in again: numpy-heavy stages ran up to
#: 1.6x slower in a worker than in this process (evaluate 8.4-9.9 s vs 5.4-6.2 s); keep glibc's
#: default. (Workers of an existing cluster keep whatever their own config says.)
NO_MALLOC_TRIM = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}

#: Thread-pool sizes of the numerical libraries, read by each worker process at start
THREAD_ENV = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def worker_thread_env(workers: int, cores: int | None = None) -> dict[str, str]:
    """Environment for local Dask workers: the machine's cores shared out between them.

    Each worker would otherwise size its numba (FEM solve), OpenMP and BLAS pools to every
    core, and workers x cores spinning threads on the same cores ran slower than one process.
    """
    per_worker = max(1, (cores or os.cpu_count() or 1) // max(1, workers))
    return {name: str(per_worker) for name in THREAD_ENV}


def _prefect_api() -> tuple[str, Callable[[], str]]:
    """PREFECT_API_URL for local workers (this process's server) and a function that starts
    that server if need be and returns its final URL.

    Without it every worker process starts a temporary Prefect server of its own (about 15 s
    of CPU each, measured here) to report its task runs to. The URL is known before the
    server is up, so the workers can start while it comes up.
    """
    from prefect.settings import PREFECT_API_URL

    if PREFECT_API_URL.value():
        url = str(PREFECT_API_URL.value())
        return url, lambda: url
    from prefect.server.api.server import SubprocessASGIServer

    server = SubprocessASGIServer()  # the instance the flow run in this process will use
    if not server.running and server.port is None:
        server.port = server.find_available_port()

    def start() -> str:
        server.start()
        return server.api_url

    return server.api_url, start


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
    path: Path, *, dask_address: str | None = None, workers: int = 2, serial: bool = False
) -> SweepOutcome:
    """Run a sweep; ``serial`` runs the jobs one by one in this process (reference timing)."""
    pipeline, variants, configs, keys, jobs = plan_sweep(path)
    run_dir = configs[variants[0].name].dataset.run_dir
    t0 = time.perf_counter()
    closing = None
    if serial:
        results = [execute_stage(pipeline, configs[j.variant], j.entry) for j in jobs]
    elif jobs:
        scratch = Path(run_dir).resolve() / "dask"
        scratch.mkdir(parents=True, exist_ok=True)
        os.environ.setdefault("DASK_TEMPORARY_DIRECTORY", str(scratch))
        local = None
        if not dask_address:
            url, start_server = _prefect_api()
            env = {**worker_thread_env(workers), "PREFECT_API_URL": url}
            local = LocalDask(workers, scratch, env)
            try:
                if start_server() != url:  # the server had to move to another port: restart
                    local.close_in_background().join()
                    local = LocalDask(workers, scratch, {**env, "PREFECT_API_URL": start_server()})
                dask_address = local.wait()
            except BaseException:
                local.close_in_background().join()
                raise
        runner = DaskTaskRunner(address=dask_address)
        dumped = {k: c.model_dump(mode="json") for k, c in configs.items()}
        try:
            results = sweep_flow.with_options(task_runner=runner)(pipeline, dumped, jobs)
        finally:
            if local is not None:
                closing = local.close_in_background()
    else:
        results = []
    seconds = time.perf_counter() - t0

    try:
        summary, report = _record_sweep(
            Path(path), pipeline, variants, configs, keys, list(results), seconds, Path(run_dir)
        )
    finally:
        if closing is not None:
            closing.join()
    return SweepOutcome(keys, list(results), seconds, summary, report)


def _record_sweep(
    path: Path,
    pipeline: Pipeline,
    variants: list[Variant],
    configs: dict[str, Any],
    keys: dict[str, dict[str, str]],
    results: list[StageResult],
    seconds: float,
    run_dir: Path,
) -> tuple[Path, Path]:
    """Record each variant as a run of its store (not the latest), write the sweep's
    summary.json and report (HTML); returns their paths."""
    report_variants = []
    for v in variants:
        store = StageStore(configs[v.name].dataset.store_path)
        done = {stage: key for stage, key in keys[v.name].items() if store.has(stage, key)}
        info = {"sweep": str(path), "variant": v.name, "configs": list(v.configs)}
        record_run(store, pipeline, done, {**info, "overrides": list(v.overrides)}, latest=False)
        report_variants.append(
            SweepVariant(
                name=v.name,
                dataset=v.dataset,
                configs=v.configs,
                overrides=v.overrides,
                keys=keys[v.name],
                summaries={s: store.provenance(s, k).get("summary", {}) for s, k in done.items()},
                files={s: store.files(s, k) for s, k in done.items()},
            )
        )
    out = run_dir / "sweeps" / path.stem
    out.mkdir(parents=True, exist_ok=True)
    record = {
        "sweep": str(path),
        "seconds": seconds,
        "variants": [
            {
                "variant": v.name,
                "dataset": v.dataset,
                "configs": list(v.configs),
                "overrides": list(v.overrides),
                "keys": dict(v.keys),
                "summaries": dict(v.summaries),
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
        title=f"Sweep {path.stem}",
        variants=report_variants,
        results=list(results),
        seconds=seconds,
        subtitle=f"{path}: {pipeline.name} pipeline,",
    )
    return out / "summary.json", report
