"""Stage registry types, planning (status) and execution of stage DAGs; never imports Prefect."""

from physanim.pipeline.context import ProgressFactory, ProgressFn, StageContext
from physanim.pipeline.executor import (
    Executor,
    Job,
    LocalExecutor,
    execute_plan_locally,
    run_jobs,
    run_plan,
    stage_inputs,
)
from physanim.pipeline.plan import PlanEntry, make_plan
from physanim.pipeline.runner import StageFailed, StageResult, execute_stage, record_run
from physanim.pipeline.spec import (
    DatasetParams,
    Pipeline,
    PipelineConfig,
    StageOutput,
    StageSpec,
    Summary,
)

__all__ = [
    "DatasetParams",
    "Executor",
    "Job",
    "LocalExecutor",
    "PlanEntry",
    "Pipeline",
    "PipelineConfig",
    "ProgressFactory",
    "ProgressFn",
    "StageContext",
    "StageFailed",
    "StageOutput",
    "StageResult",
    "StageSpec",
    "Summary",
    "execute_plan_locally",
    "execute_stage",
    "make_plan",
    "record_run",
    "run_jobs",
    "run_plan",
    "stage_inputs",
]
