"""Executors: one interface and one submit loop for every way physanim runs planned stages.

A plan (one store) or a sweep (many stores) becomes a list of ``Job``s, each naming the jobs
it waits for. An ``Executor`` runs such a list (``run``) and releases what it started
(``close``); ``run_jobs`` is the only loop that submits a job graph and collects what became
of each job, through a ``Submitter`` (how one job is started, given the handles of its
upstream jobs, and awaited). ``LocalExecutor`` runs the jobs in this process, in order;
``flows.executors`` adds Prefect (a task per job, on threads) and Dask (the same tasks on a
cluster). ``run_plan`` runs one store's plan with any executor and records the run.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any, Protocol

from physanim.pipeline.context import ProgressFactory
from physanim.pipeline.plan import PlanEntry, make_plan
from physanim.pipeline.runner import StageFailed, StageResult, execute_stage, record_run
from physanim.pipeline.spec import Pipeline, PipelineConfig
from physanim.store import StageStore, read_dataclass

#: (store path, stage, key): one distinct stage execution
Ident = tuple[str, str, str]
#: What became of one job: its result, its error, or None (an upstream job failed)
Outcome = StageResult | BaseException | None
#: Called with each result as it is collected
OnResult = Callable[[StageResult], None] | None
#: The variant name of a plain run's jobs (a sweep names its variants)
RUN = "run"


@dataclass(frozen=True)
class Job:
    """One distinct stage execution, identified by (store, stage, key)."""

    store: str
    entry: PlanEntry
    variant: str  # the first variant that needs it; its config is used to run it
    deps: tuple[Ident, ...]  # (store, stage, key) of upstream jobs

    @property
    def ident(self) -> Ident:
        """(store, stage, key)."""
        return (self.store, self.entry.stage, self.entry.key)


def merge_plans(plans: Mapping[str, tuple[str, list[PlanEntry]]]) -> list[Job]:
    """One job per distinct (store, stage, key) to run, in an order where deps come first.

    ``plans`` maps variant name -> (store path, plan entries).
    """
    jobs: dict[Ident, Job] = {}
    for variant, (store, entries) in plans.items():
        for e in entries:
            if e.action != "run":
                continue
            ident = (store, e.stage, e.key)
            if ident not in jobs:
                deps = tuple((store, u, k) for u, k in e.upstream.items())
                jobs[ident] = Job(store, e, variant, deps)
    return list(jobs.values())


@dataclass(frozen=True)
class JobGraph:
    """What an executor runs: the pipeline, each variant's config (name -> validated config,
    or its plain dict on Dask) and the jobs, deps first."""

    pipeline: Pipeline
    configs: Mapping[str, Any]
    jobs: list[Job]


def blocked(job: Job, outcomes: Mapping[Ident, object]) -> bool:
    """True when an upstream job of ``job`` ran in this graph and did not succeed."""
    return any(d in outcomes and not isinstance(outcomes[d], StageResult) for d in job.deps)


class Submitter(Protocol):
    """How one job is started and awaited: what ``run_jobs`` needs of an executor."""

    def submit(self, pipeline: Pipeline, config: Any, job: Job, deps: list[Any]) -> Any:
        """Start ``job`` once the jobs behind the handles ``deps`` are done; its handle."""
        ...

    def wait(self, handle: Any) -> None:
        """Wait until the job of ``handle`` has finished (or will never start)."""
        ...

    def result(self, handle: Any) -> StageResult:
        """The result of a finished job; raises its error."""
        ...


class Executor:
    """Runs a job graph: ``run`` submits the jobs through a Submitter with ``run_jobs``
    (Prefect's executor does so inside a flow run); ``close`` releases what ``run`` started
    (a cluster); executors are context managers that close on exit."""

    def run(self, graph: JobGraph, on_result: OnResult = None) -> list[Outcome]:
        """What became of each job of ``graph`` (same order); ``on_result`` sees each result."""
        raise NotImplementedError

    def close(self) -> None:
        """Release what ``run`` started."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_jobs(submitter: Submitter, graph: JobGraph, on_result: OnResult = None) -> list[Outcome]:
    """The submit loop: submit every job after its upstream jobs, then collect them in order.

    A failed job fails only the jobs downstream of it (outcome None); the others run to the
    end. ``on_result`` sees each result as it is collected.
    """
    handles: dict[Ident, Any] = {}
    for job in graph.jobs:
        deps = [handles[d] for d in job.deps if d in handles]
        config = graph.configs[job.variant]
        handles[job.ident] = submitter.submit(graph.pipeline, config, job, deps)
    outcomes: dict[Ident, Outcome] = {}
    for job in graph.jobs:  # deps come first
        submitter.wait(handles[job.ident])
        if blocked(job, outcomes):
            outcomes[job.ident] = None
            continue
        try:
            result = submitter.result(handles[job.ident])
        except Exception as exc:  # the stage's error, or a worker lost too often (KilledWorker)
            outcomes[job.ident] = exc
            continue
        outcomes[job.ident] = result
        if on_result is not None:
            on_result(result)
    return [outcomes[job.ident] for job in graph.jobs]


class LocalExecutor(Executor):
    """This process, one job after another (tests, debugging, ``--local``, ``--serial``);
    a job runs when its result is asked for, so a blocked job never runs."""

    def __init__(self, progress: ProgressFactory | None = None) -> None:
        self.progress = progress

    def run(self, graph: JobGraph, on_result: OnResult = None) -> list[Outcome]:
        return run_jobs(self, graph, on_result)

    def submit(
        self, pipeline: Pipeline, config: Any, job: Job, deps: list[Any]
    ) -> Callable[[], StageResult]:
        return partial(execute_stage, pipeline, config, job.entry, self.progress)

    def wait(self, handle: Callable[[], StageResult]) -> None:
        """Nothing to wait for: the job runs in ``result``."""

    def result(self, handle: Callable[[], StageResult]) -> StageResult:
        return handle()


def run_plan(
    executor: Executor,
    pipeline: Pipeline,
    config: PipelineConfig,
    entries: list[PlanEntry],
    on_result: OnResult = None,
    info: Mapping[str, Any] | None = None,
) -> list[StageResult]:
    """Run one store's plan with ``executor`` and record it as the latest run (also when a
    stage failed: what completed is kept; not when the store itself failed); ``info`` goes
    into the run manifest. Returns the cached and ran results in plan order; raises the
    first job's error after every independent job has finished."""
    store = StageStore(config.dataset.store_path)
    store.remove_stale_temporaries()
    cached = [
        StageResult(e.stage, e.key, "cached", 0.0, {}) for e in entries if e.action == "cached"
    ]
    for r in cached if on_result is not None else ():
        on_result(r)
    graph = JobGraph(pipeline, {RUN: config}, merge_plans({RUN: (str(store.root), entries)}))
    outcomes = executor.run(graph, on_result) if graph.jobs else []
    errors = [o for o in outcomes if isinstance(o, BaseException)]
    if all(isinstance(e, StageFailed) for e in errors):
        record_run(store, pipeline, {e.stage: e.key for e in entries}, info)
    if errors:
        raise errors[0]
    done = {r.stage: r for r in [*cached, *outcomes] if isinstance(r, StageResult)}
    return [done[e.stage] for e in entries if e.stage in done]


def execute_plan_locally(
    pipeline: Pipeline,
    config: PipelineConfig,
    entries: list[PlanEntry],
    progress: ProgressFactory | None = None,
    on_result: OnResult = None,
    info: Mapping[str, Any] | None = None,
) -> list[StageResult]:
    """``run_plan`` in this process, without Prefect (tests, debugging, ``--local``)."""
    return run_plan(LocalExecutor(progress), pipeline, config, entries, on_result, info)


def stage_inputs(
    pipeline: Pipeline,
    config: PipelineConfig,
    stage: str,
    progress: ProgressFactory | None = None,
) -> dict[str, Any]:
    """The typed outputs ``stage`` reads (upstream stage name -> output dataclass), after
    preparing the dataset and computing, in this process, whichever upstream outputs the store
    lacks (benchmarks and notebooks that run one stage's computation by hand)."""
    if pipeline.prepare is not None:
        pipeline.prepare(config, progress)
    store = StageStore(config.dataset.store_path)
    needed = pipeline.upstream(stage)[:-1]
    plan = [e for e in make_plan(pipeline, config, store) if e.stage in needed]
    execute_plan_locally(pipeline, config, plan, progress)
    key = {e.stage: e.key for e in plan}
    inputs = {}
    for name in pipeline.stage(stage).upstream:
        output = pipeline.stage(name).output
        if output is None:
            raise TypeError(f"stage {name} declares no output dataclass (StageSpec.typed)")
        inputs[name] = read_dataclass(output, store.open(name, key[name]))
    return inputs
