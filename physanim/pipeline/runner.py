"""Execute one planned stage: compute into a temporary group, commit atomically; record runs."""

from __future__ import annotations

import math
import os
import socket
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from physanim.pipeline.context import ProgressFactory, StageContext, _no_progress
from physanim.pipeline.plan import PlanEntry
from physanim.pipeline.spec import Pipeline, PipelineConfig
from physanim.store import StageStore

_HOST = socket.gethostname()


class StageFailed(RuntimeError):
    """A stage's compute raised; the message names the stage and the original error."""

    def __init__(self, stage: str, error: BaseException) -> None:
        super().__init__(f"stage '{stage}' failed: {type(error).__name__}: {error}")
        self.stage = stage

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as stage and message: Dask and Prefect send it from a worker."""
        return (_stage_failed, (self.stage, str(self)))


def _stage_failed(stage: str, message: str) -> StageFailed:
    """A StageFailed with this stage and message (unpickling)."""
    exc = StageFailed.__new__(StageFailed)
    RuntimeError.__init__(exc, message)
    exc.stage = stage
    return exc


@dataclass(frozen=True)
class StageResult:
    """Outcome of one stage in a run: ``ran`` or ``cached``, with its wall time in seconds.

    ``started``: Unix time (s) the stage began; ``worker``: ``host:pid`` of the process that
    ran it (sweep timelines).
    """

    stage: str
    key: str
    action: str
    seconds: float
    summary: Mapping[str, Any]
    started: float = 0.0
    worker: str = ""


def execute_stage(
    pipeline: Pipeline,
    config: PipelineConfig | Mapping[str, Any],
    entry: PlanEntry,
    progress: ProgressFactory | None = None,
) -> StageResult:
    """Run one planned stage and commit its output (``config`` may be a plain dict: workers).

    If the output appeared meanwhile (another worker), nothing is recomputed.  A forced stage
    replaces its existing output only once the new one is complete.
    """
    if not isinstance(config, PipelineConfig):
        config = pipeline.config_model().model_validate(config)
    spec = pipeline.stage(entry.stage)
    dataset = config.dataset
    store = StageStore(dataset.store_path)
    t0, started = time.perf_counter(), time.time()
    if not entry.forced and store.has(spec.name, entry.key):
        return StageResult(spec.name, entry.key, "cached", 0.0, {})
    params = spec.params_from(config)
    provenance = {
        "version": spec.version,
        "params": params.model_dump(mode="json"),
        "key_params": dict(entry.params),
        "upstream": dict(entry.upstream),
        "varying_inputs": _varying_inputs(pipeline, store, entry.upstream),
        "pipeline": pipeline.name,
    }
    with store.writing(spec.name, entry.key, provenance, replace=entry.forced) as group:
        ctx = StageContext(
            spec=spec,
            params=params,
            key=entry.key,
            upstream=entry.upstream,
            store=store,
            dataset=dataset,
            out=group,
            progress=progress or _no_progress,
        )
        try:
            summary = flag_nan_figures(dict(spec.compute(ctx) or {}))
        except Exception as exc:
            raise StageFailed(spec.name, exc) from exc
        if summary:
            group.attrs["summary"] = summary
    seconds = time.perf_counter() - t0
    return StageResult(
        spec.name, entry.key, "ran", seconds, summary, started, f"{_HOST}:{os.getpid()}"
    )


def _nan_figures(value: Any, name: str = "") -> list[str]:
    """Dotted names of the NaN numbers in a summary value (nested dicts and lists)."""
    if isinstance(value, float) and math.isnan(value):
        return [name]
    if isinstance(value, Mapping):
        return [n for k, v in value.items() for n in _nan_figures(v, f"{name}.{k}" if name else k)]
    if isinstance(value, list | tuple):
        return [n for i, v in enumerate(value) for n in _nan_figures(v, f"{name}[{i}]")]
    return []


def flag_nan_figures(summary: dict[str, Any]) -> dict[str, Any]:
    """``summary`` with a warning naming its NaN figures, if any (a figure that could not be
    computed must not pass as a number: the CLI prints the warning, the report shows it)."""
    nan = _nan_figures({k: v for k, v in summary.items() if k != "warnings"})
    if not nan:
        return summary
    shown = ", ".join(nan[:6]) + (f" and {len(nan) - 6} more" if len(nan) > 6 else "")
    warning = f"{len(nan)} figure(s) of this stage are NaN (not computed): {shown}"
    return {**summary, "warnings": [*summary.get("warnings", []), warning]}


def _varying_inputs(
    pipeline: Pipeline, store: StageStore, upstream: Mapping[str, str]
) -> dict[str, dict[str, str | None]]:
    """stage -> {key, digest} of every output of a ``varies`` stage that ``upstream``
    (stage -> key) was computed from, directly or through its own inputs."""
    out: dict[str, dict[str, str | None]] = {}
    for stage, key in upstream.items():
        out.update(store.varying_inputs(stage, key))
        if pipeline.stage(stage).varies:
            out[stage] = {"key": key, "digest": store.content_digest(stage, key)}
    return out


def record_run(
    store: StageStore,
    pipeline: Pipeline,
    planned: Mapping[str, str],
    info: Mapping[str, Any] | None = None,
    *,
    latest: bool = True,
) -> str | None:
    """Write the run manifest of a run: the planned keys (stage -> key) whose output exists.

    ``complete`` in the manifest says whether every stage of the pipeline has its output;
    ``latest`` makes it the store's LATEST run.  Returns the manifest's name (None: no output
    exists, nothing is recorded).  Outputs of a store from before run manifests are first
    recorded as runs of their own.
    """
    keys = {stage: key for stage, key in planned.items() if store.has(stage, key)}
    if not keys:
        return None
    stages = [s.name for s in pipeline.stages]
    store.adopt_unrecorded(pipeline.name, stages)
    complete = all(s in keys for s in stages)
    facts = {"pipeline": pipeline.name, "complete": complete, **(info or {})}
    return store.record_run(keys, facts, latest=latest)
