"""The Prefect flow that runs any physanim pipeline: one Prefect task per stage.

Tasks pass store keys, never arrays: each task writes its output to the stage store and
returns a small StageResult.  Import this module only after ``prefect_env.configure``.
"""

from __future__ import annotations

from prefect import flow, task
from prefect.cache_policies import NONE
from pydantic import BaseModel

from physanim.native import load_in_main_thread
from physanim.pipeline import (
    Pipeline,
    PlanEntry,
    ProgressFactory,
    StageResult,
    execute_stage,
)


@task(cache_policy=NONE, persist_result=False)
def stage_task(
    pipeline: Pipeline, config: BaseModel, entry: PlanEntry, progress: ProgressFactory | None
) -> StageResult:
    """Run one stage (compute, commit to the store); named after the stage at submit time."""
    return execute_stage(pipeline, config, entry, progress)


@flow(name="physanim-pipeline", persist_result=False, validate_parameters=False)
def pipeline_flow(
    pipeline: Pipeline,
    config: BaseModel,
    entries: list[PlanEntry],
    progress: ProgressFactory | None = None,
) -> list[StageResult]:
    """Submit every planned stage as a task, each waiting for its upstream stages' tasks."""
    if any(e.action == "run" for e in entries):
        load_in_main_thread()  # before the task threads import them (see physanim.native)
    futures = {}
    for e in entries:
        if e.action != "run":
            continue
        deps = [futures[u] for u in e.upstream if u in futures]
        named = stage_task.with_options(name=e.stage, task_run_name=f"{e.stage}-{e.key[:8]}")
        futures[e.stage] = named.submit(pipeline, config, e, progress, wait_for=deps)
    return [f.result() for f in futures.values()]
