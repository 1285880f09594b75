"""Prefect's overhead on a no-op run of a face-shaped DAG, side by side with the local runner.

Prints wall times for: the local in-process runner, the first Prefect flow run (which starts a
temporary API server with a fresh PREFECT_HOME), and a second flow run in the same process;
then whole ``physanim run`` commands: ``--local``, the first Prefect run of a run directory
(which starts its shared server) and the next ones (which reuse it), medians of 3.

Run: .venv/bin/python benchmarks/bench_prefect_overhead.py
"""

from __future__ import annotations

import functools
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pydantic import BaseModel, ConfigDict

from flows.dags import FACE
from physanim.config import load_config
from physanim.pipeline import Pipeline, StageSpec, execute_plan_locally, make_plan, run_plan
from physanim.store import StageStore

#: The face DAG's stages, in order (the no-op DAG copies their names)
NAMES = tuple(s.name for s in FACE.stages)


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


#: The no-op DAG as the CLI addresses it: ``-p benchmarks.bench_prefect_overhead:NOOP``.
NOOP = noop_dag(Path(__file__).with_name("noop_default.yaml"))


def cli_runs(repeats: int = 3) -> list[list]:
    """Wall time of whole ``physanim run`` commands on the no-op DAG (fresh stage keys)."""
    root = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PREFECT_", "PHYSANIM_"))}
    with tempfile.TemporaryDirectory() as tmp:
        salt = iter(range(100, 10_000))

        def run(*extra: str) -> float:
            cmd = [
                sys.executable,
                "-m",
                "cli",
                "run",
                "-p",
                "benchmarks.bench_prefect_overhead:NOOP",
            ]
            cmd += ["--dataset", f"{tmp}/noop", "--set", f"ingest.salt={next(salt)}", *extra]
            t0 = time.perf_counter()
            subprocess.run(cmd, cwd=root, env=env, check=True, capture_output=True)
            return time.perf_counter() - t0

        local = [run("--local") for _ in range(repeats)]
        first = run()
        reuse = [run() for _ in range(repeats)]
        state = Path(tmp) / "noop" / "runs" / "prefect" / "server.json"
        if state.exists():  # stop the shared server now rather than after its idle time
            os.kill(json.loads(state.read_text())["pid"], signal.SIGTERM)
            while state.exists():
                time.sleep(0.2)
    med_local, med_reuse = statistics.median(local), statistics.median(reuse)
    print("physanim run on the no-op DAG (whole command; medians of 3):")
    rows = (("--local", med_local), ("prefect, first run (starts server)", first),
            ("prefect, next runs (reuse it)", med_reuse))  # fmt: skip
    for name, wall in rows:
        print(f"  {name:34s}: {wall:6.2f} s  (+{wall - med_local:5.2f} s over --local)")
    return [[name, wall, wall - med_local] for name, wall in rows]


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
        from flows.executors import PrefectExecutor  # no home: Prefect's temporary server

        in_prefect = functools.partial(run_plan, PrefectExecutor(None, name="physanim-noop"))
        first = timed(in_prefect, 1)
        second = timed(in_prefect, 2)
    print(f"no-op DAG of {len(NAMES)} stages, python {sys.version.split()[0]}")
    print(f"  local runner           : {local:6.2f} s")
    print(f"  prefect, first flow run: {first:6.2f} s  (overhead {first - local:5.2f} s)")
    print(f"  prefect, second run    : {second:6.2f} s  (overhead {second - local:5.2f} s)")
    cli = cli_runs()
    # imported here: the CLI imports this module as benchmarks.bench_prefect_overhead
    from results import Table, describe, record

    in_process = [["local runner", local, 0.0], ["prefect, first flow run", first, first - local],
                  ["prefect, second run", second, second - local]]  # fmt: skip
    columns = ["runner", "wall_s", "over_local_s"]
    record(
        "bench_prefect_overhead",
        [
            Table(f"no-op DAG of {len(NAMES)} stages, in this process", columns, in_process),
            Table("physanim run on the no-op DAG (whole command; medians of 3)", columns, cli),
        ],  # fmt: skip
        **describe(__doc__, "bench_prefect_overhead"),
        headline={"local_s": cli[0][1], "prefect_first_s": cli[1][1], "prefect_next_s": cli[2][1]},
    )


if __name__ == "__main__":
    main()
