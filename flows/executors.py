"""Prefect and Dask executors (``physanim.pipeline.executor``): one Prefect task per job.

``PrefectExecutor`` runs ``run_jobs`` (the one submit loop) inside a Prefect flow run with
``PrefectTasks`` as its Submitter (a Prefect task per job, waiting for its upstream tasks),
on Prefect's thread pool; ``DaskExecutor`` is the same flow with Dask's task runner, on a
local cluster started for the run or an existing one. Tasks pass store keys, never arrays:
each writes its output to the stage store and returns a small StageResult. The Prefect API is
the run directory's shared server (``prefect_env.shared_server``), or PREFECT_API_URL when it
answers. Import this module only after ``prefect_env.configure``.
"""

from __future__ import annotations

import contextlib
import os
import socket
import threading
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from distributed import Client
from prefect import Task, flow, task
from prefect.cache_policies import NONE
from prefect.futures import PrefectFuture
from prefect.settings import (
    PREFECT_API_URL,
    PREFECT_FLOWS_HEARTBEAT_FREQUENCY,
    temporary_settings,
)
from prefect_dask import DaskTaskRunner
from pydantic import BaseModel

from flows.dask_cluster import LocalDask, check_workers, connect, worker_thread_env
from flows.prefect_env import shared_server
from physanim.native import load_in_main_thread
from physanim.pipeline import Executor, Job, Pipeline, ProgressFactory, StageResult, run_jobs
from physanim.pipeline.executor import JobGraph, OnResult, Outcome
from physanim.pipeline.runner import execute_stage


@task(cache_policy=NONE, persist_result=False)
def stage_task(
    pipeline: Pipeline,
    config: BaseModel | dict[str, Any],
    job: Job,
    cwd: str,
    progress: ProgressFactory | None,
) -> StageResult:
    """Run one job (compute, commit to the store) in the run's working directory (relative
    paths in configs mean the same on every Dask worker); named after the stage."""
    if os.getcwd() != cwd:
        try:
            os.chdir(cwd)
        except OSError as exc:
            raise RuntimeError(
                f"worker {socket.gethostname()}:{os.getpid()} cannot enter the run's working "
                f"directory {cwd} ({exc.strerror}): the workers must see the same files at the "
                "same paths (this machine, or a shared file system)"
            ) from None
    return execute_stage(pipeline, config, job.entry, progress)


@dataclass(frozen=True)
class PrefectTasks:
    """The Submitter inside the flow run: a Prefect task per job, run in ``cwd`` (picklable:
    Dask sends it with the flow run's context), ``progress`` for stages run in this process."""

    cwd: str
    progress: ProgressFactory | None = None

    def submit(self, pipeline: Pipeline, config: Any, job: Job, deps: list[Any]) -> PrefectFuture:
        e = job.entry
        named: Task = stage_task.with_options(name=e.stage, task_run_name=f"{e.stage}-{e.key[:8]}")
        return named.submit(pipeline, config, job, self.cwd, self.progress, wait_for=deps)

    def wait(self, handle: PrefectFuture) -> None:
        handle.wait()

    def result(self, handle: PrefectFuture) -> StageResult:
        return handle.result()


@flow(name="physanim", persist_result=False, validate_parameters=False)
def jobs_flow(tasks: PrefectTasks, graph: JobGraph, on_result: OnResult) -> list[Outcome]:
    """The job graph as one flow run: the submit loop, submitting Prefect tasks."""
    return run_jobs(tasks, graph, on_result)


class PrefectExecutor(Executor):
    """Every job a Prefect task of one flow run named ``name``, on Prefect's thread pool.

    ``home``: the Prefect home whose shared server to use (None: the API already configured,
    e.g. inside a served flow); ``progress`` reaches the stages (they run in this process).
    """

    def __init__(
        self,
        home: Path | None,
        *,
        name: str = "physanim",
        progress: ProgressFactory | None = None,
    ) -> None:
        self.home, self.name, self.progress = home, name, progress
        self.cwd = os.getcwd()

    @contextlib.contextmanager
    def api(self) -> Iterator[str]:
        """The Prefect API URL that the flow reports to while the context lasts."""
        if self.home is None:
            yield str(PREFECT_API_URL.value() or "")
            return
        # no flow-run heartbeats: the command that runs the flow reports its end itself, and
        # stopping the heartbeat thread cost every run up to a second (it sleeps in 1 s steps)
        with (
            shared_server(self.home) as (url, _),
            temporary_settings({PREFECT_API_URL: url, PREFECT_FLOWS_HEARTBEAT_FREQUENCY: None}),
        ):
            yield url  # the flow's settings, handed to every task (on Dask workers too)

    def task_runner(self, api_url: str) -> DaskTaskRunner | None:
        """The flow's task runner (None: Prefect's thread pool)."""
        return None

    def run(self, graph: JobGraph, on_result: OnResult = None) -> list[Outcome]:
        with self.api() as url:
            runner = self.task_runner(url)
            if runner is None:
                load_in_main_thread()  # before the task threads import them (physanim.native)
            named = jobs_flow.with_options(name=self.name, task_runner=runner)
            return named(PrefectTasks(self.cwd, self.progress), graph, on_result)


class DaskExecutor(PrefectExecutor):
    """The Prefect flow on Dask: on the scheduler at ``address``, or on a local cluster of
    ``workers`` processes (``worker_threads`` numerical threads each; default: the cores
    shared out) started for the run in the background and closed by ``close``."""

    def __init__(
        self,
        home: Path | None,
        *,
        name: str = "physanim",
        address: str | None = None,
        workers: int = 2,
        worker_threads: int | None = None,
        scratch: Path,
    ) -> None:
        super().__init__(home, name=name)
        self.address, self.workers, self.worker_threads = address, workers, worker_threads
        self.scratch = scratch
        self._local: LocalDask | None = None
        self._client: Client | None = None
        self._closing: threading.Thread | None = None

    def run(self, graph: JobGraph, on_result: OnResult = None) -> list[Outcome]:
        self.scratch.mkdir(parents=True, exist_ok=True)
        os.environ.setdefault("DASK_TEMPORARY_DIRECTORY", str(self.scratch))
        env = worker_thread_env(self.workers, per_worker=self.worker_threads)
        # the cluster comes up (in the background) while Prefect's server does
        self._local = None if self.address else LocalDask(self.workers, self.scratch, env)
        self._client = connect(self.address) if self.address else None
        dumped = {k: _plain(c) for k, c in graph.configs.items()}  # the workers re-validate
        try:
            outcomes = super().run(replace(graph, configs=dumped), on_result)
        except BaseException:
            if self._local is not None:
                self._local.close_in_background().join()
            raise
        if self._local is not None:
            self._closing = self._local.close_in_background()  # while the caller reports
        return outcomes

    def task_runner(self, api_url: str) -> DaskTaskRunner:
        if self._client is not None:
            with self._client:
                check_workers(self._client, str(self.address), "//127.0.0.1" in api_url)
        address = self._local.wait() if self._local is not None else self.address
        return DaskTaskRunner(address=address)

    def close(self) -> None:
        if self._closing is not None:
            self._closing.join()
            self._closing = None


def _plain(config: Any) -> Any:
    """A config as a plain dict (config models are built at run time: they do not pickle)."""
    return config.model_dump(mode="json") if isinstance(config, BaseModel) else config
