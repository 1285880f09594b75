"""The real Prefect flow runs the DAG hermetically (Prefect home inside the run directory)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from physanim.store import StageStore
from tests.foundation.toy_stages import executions

ROOT = Path(__file__).resolve().parents[2]


def test_flow_runs_each_stage_as_a_prefect_task(toy_config: Path, tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    env.update(PYTHONPATH=str(ROOT), HOME=str(tmp_path / "home"))
    args = [sys.executable, "-m", "cli", "run", "-p", "tests.foundation.toy_stages:TOY"]
    args += ["-c", str(toy_config)]
    out = subprocess.run(args, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert executions(tmp_path) == ["source", "scale", "total"]
    run_dir = tmp_path / "data" / "runs"
    assert (run_dir / "prefect").is_dir()  # hermetic: Prefect's home is inside the run dir
    assert any((run_dir / "prefect").iterdir())
    assert not (tmp_path / "home" / ".prefect").exists()  # the user's profile is untouched
    store = StageStore(run_dir / "store.zarr")
    assert float(store.open("total")["total"][0]) == 2 * (499500 * 8 + 1000 * 28)

    # all cached: the second run does not start Prefect and computes nothing
    again = subprocess.run(args, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0 and "0 stage(s) ran" in again.stderr
    assert executions(tmp_path) == []
