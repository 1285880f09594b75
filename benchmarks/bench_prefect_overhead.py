"""Prefect's overhead on a no-op run of a face-shaped DAG, side by side with the local runner.

Prints wall times for: the local in-process runner, the first Prefect flow run (which starts a
temporary API server with a fresh PREFECT_HOME), and a second flow run in the same process.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from pydantic import BaseModel, ConfigDict

from physanim.config import load_config
from physanim.pipeline import Pipeline, StageSpec, execute_plan_locally, make_plan
from physanim.store import StageStore

NAMES = ("ingest", "track", "fit", "align", "tetra", "materials", "simulate", "evaluate", "render")


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    salt: int = 0


def noop(ctx) -> None:
    ctx.out.attrs["noop"] = True


def noop_dag(default: Path) -> Pipeline:
    stages, up = [], ()
    for n in NAMES:
        stages.append(StageSpec(n, up, NoParams, "1", noop))
        up = (n,)
    return Pipeline("noop", tuple(stages), default)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        cfg_file = Path(tmp) / "c.yaml"
        cfg_file.write_text(f"dataset:\n  name: noop\n  dir: {tmp}/data\n")
        dag = noop_dag(cfg_file)

        def timed(runner, salt: int) -> float:
            cfg, _ = load_config(dag.config_model(), [cfg_file], [f"ingest.salt={salt}"])
            plan = make_plan(dag, cfg, StageStore(cfg.dataset.store_path))
            t0 = time.perf_counter()
            runner(dag, cfg, plan)
            return time.perf_counter() - t0

        local = timed(execute_plan_locally, 0)
        from flows.prefect_env import configure

        configure(Path(tmp) / "data" / "runs")
        from flows.pipeline_flow import pipeline_flow

        first = timed(pipeline_flow, 1)
        second = timed(pipeline_flow, 2)
    print(f"no-op DAG of {len(NAMES)} stages, python {sys.version.split()[0]}")
    print(f"  local runner           : {local:6.2f} s")
    print(f"  prefect, first flow run: {first:6.2f} s  (overhead {first - local:5.2f} s)")
    print(f"  prefect, second run    : {second:6.2f} s  (overhead {second - local:5.2f} s)")


if __name__ == "__main__":
    main()
