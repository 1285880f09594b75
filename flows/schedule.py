"""Scheduled batch runs: a Prefect deployment that runs a pipeline on every dataset in a folder.

``serve`` needs a real Prefect API server (Prefect refuses to schedule on its temporary one);
``prefect_env.prefect_server`` provides it.  Each scheduled run scans the folder; every
sub-directory is a dataset.  Because outputs are content-addressed, datasets that did not
change are pure cache hits, and new or changed ones run, each as a flow run of its own whose
tasks are its stages (``flows.executors.PrefectExecutor``).
Import only after ``prefect_env.configure``.
"""

from __future__ import annotations

from pathlib import Path

from prefect import flow, get_run_logger

from flows.dags import get_pipeline
from flows.executors import PrefectExecutor
from physanim.config import ConfigError, load_config
from physanim.pipeline import StageFailed, make_plan, run_plan
from physanim.pipeline.spec import dataset_overrides
from physanim.store import StageStore


@flow(name="physanim-batch", persist_result=False)
def batch_flow(
    datasets_dir: str, pipeline: str = "face", configs: list[str] | None = None
) -> dict[str, str]:
    """Run ``pipeline`` on every dataset under ``datasets_dir``; returns dataset -> outcome."""
    log = get_run_logger()
    dag = get_pipeline(pipeline)
    outcome: dict[str, str] = {}
    for d in sorted(p for p in Path(datasets_dir).iterdir() if p.is_dir()):
        if d.name.startswith("."):
            continue
        try:
            cfg, _ = load_config(
                dag.config_model(),
                [dag.default_config, *(configs or [])],
                dataset_overrides(str(d)),
            )
            store = StageStore(cfg.dataset.store_path)
            executor = PrefectExecutor(None, name=f"physanim-{dag.name}-{d.name}")
            results = run_plan(executor, dag, cfg, make_plan(dag, cfg, store))
            ran = [r.stage for r in results if r.action == "ran"]
            outcome[d.name] = f"ran {', '.join(ran)}" if ran else "up to date"
        except (ConfigError, ValueError, OSError, StageFailed) as exc:  # one bad dataset
            # (or a stage failing on it) must not stop a batch
            outcome[d.name] = f"failed: {exc}"
            log.error("dataset %s failed: %s", d.name, exc)
            continue
        log.info("dataset %s: %s", d.name, outcome[d.name])
    return outcome


def serve(
    datasets_dir: Path,
    *,
    pipeline: str = "face",
    configs: list[str] | None = None,
    interval_s: float | None = None,
    cron: str | None = None,
) -> None:
    """Register the batch deployment with a schedule and serve it until SIGINT/SIGTERM."""
    batch_flow.serve(
        name=f"{pipeline}-batch",
        interval=interval_s,
        cron=cron,
        parameters={
            "datasets_dir": str(Path(datasets_dir).resolve()),
            "pipeline": pipeline,
            "configs": [str(Path(c).resolve()) for c in configs or []],
        },
        print_starting_message=True,
        limit=1,  # one batch at a time; a slow batch delays the next instead of racing it
    )


def main(argv: list[str] | None = None) -> None:
    """``python -m flows.schedule DATASETS PIPELINE (--interval S | --cron EXPR) [CONFIG...]``
    (started by ``physanim serve``, which provides the Prefect server)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m flows.schedule")
    ap.add_argument("datasets", type=Path)
    ap.add_argument("pipeline")
    when = ap.add_mutually_exclusive_group(required=True)
    when.add_argument("--interval", type=float)
    when.add_argument("--cron")
    ap.add_argument("configs", nargs="*")
    a = ap.parse_args(argv)
    try:
        serve(a.datasets, pipeline=a.pipeline, configs=a.configs, interval_s=a.interval,
              cron=a.cron)  # fmt: skip
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":  # PREFECT_HOME and PREFECT_API_URL come from `physanim serve`
    main()
