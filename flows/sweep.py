"""Parameter sweeps over datasets and variants, on Dask through Prefect (prefect-dask).

Every distinct (store, stage, key) of the sweep is one job of the Dask executor
(``flows.executors``); jobs wait for their upstream jobs, so stages shared by several variants
run once and variants fan out in parallel on the Dask workers.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from flows.dags import get_pipeline
from flows.executors import DaskExecutor
from flows.prefect_env import configure
from physanim.pipeline import Executor, LocalExecutor, StageFailed, StageResult, record_run
from physanim.pipeline.sweep import SweepPlan, plan_sweep, variant_errors
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


def run_sweep(
    sweep: Path | SweepPlan,
    *,
    dask_address: str | None = None,
    workers: int = 2,
    serial: bool = False,
    worker_threads: int | None = None,
) -> SweepOutcome:
    """Run a sweep (a file, or its plan) on Dask; ``serial`` runs the jobs one by one in this
    process (reference timing). Local workers get ``worker_threads`` numerical threads each
    (default: the cores shared out). A variant whose stage fails is reported in ``errors``;
    the others run to the end."""
    plan = sweep if isinstance(sweep, SweepPlan) else plan_sweep(sweep, get_pipeline)
    t0 = time.perf_counter()
    executor: Executor = (
        LocalExecutor()
        if serial
        else DaskExecutor(
            configure(plan.run_dir),
            name="physanim-sweep",
            address=dask_address,
            workers=workers,
            worker_threads=worker_threads,
            scratch=Path(plan.run_dir).resolve() / "dask",
        )
    )
    with executor:  # a local cluster closes while the report is written
        outcomes = executor.run(plan.graph) if plan.jobs else []
        seconds = time.perf_counter() - t0
        results = [o for o in outcomes if isinstance(o, StageResult)]
        failed = {
            j.ident: _error(o)
            for j, o in zip(plan.jobs, outcomes, strict=True)
            if isinstance(o, BaseException)
        }
        errors = variant_errors(plan, failed)
        summary, report = _record_sweep(plan, results, errors, seconds)
    return SweepOutcome(plan.keys, results, errors, seconds, summary, report)


def _error(exc: BaseException) -> str:
    """One line for a failed job (StageFailed already names the stage)."""
    return str(exc) if isinstance(exc, StageFailed) else f"{type(exc).__name__}: {exc}"


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
