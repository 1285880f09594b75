"""kill -9 at random points: of a toy DAG (plain and forced runs) and of a real face stage."""

from __future__ import annotations

import random
import time
from pathlib import Path

import numpy as np
import pytest

from physanim.store import StageStore
from physanim.store.stage_store import TMP
from tests.commands import ROOT, TOY, invoke, physanim_env, start
from tests.conftest import COARSE
from tests.reliability.conftest import assert_store_tells_the_truth

STAGES = ("source", "scale", "total")


def test_kill9_at_random_points_of_a_toy_dag(toy_config: Path, tmp_path: Path) -> None:
    """Five runs killed at random moments (imports, writing, commit, run manifest): the store
    never holds a damaged or lying output, a forced stage never loses the old output, and
    the next run completes with the right numbers and no leftovers."""
    rng = random.Random(16)
    env = physanim_env(PHYSANIM_TOY_LOG=str(tmp_path / "executions.log"))
    base = ["run", "-p", TOY, "-c", str(toy_config), "--local"]
    base += ["--set", "source.slow_s=0.01", "--set", "source.n_frames=60"]
    first = invoke(*base)
    assert first.returncode == 0, first.stderr
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    good = {s: store.latest(s) for s in STAGES}
    for i in range(5):
        extra = rng.choice([["--force", "source"], ["--set", f"scale.factor={i + 3}"]])
        proc = start(*base, *extra, env=env)
        time.sleep(rng.uniform(0.8, 3.0))
        proc.kill()
        proc.wait()
        assert_store_tells_the_truth(store)
        assert all(store.has(s, k) for s, k in good.items())  # forced or not: never lost
    again = invoke(*base)
    assert again.returncode == 0, again.stderr
    assert list((store.root / TMP).iterdir()) == []
    assert {s: store.latest(s) for s in STAGES} == good
    total = float(store.open("total")["total"][0])
    assert total == pytest.approx(2 * (499500 * 60 + 1000 * sum(range(60))))


def test_kill9_in_a_forced_face_stage_keeps_the_old_output(face_copy: Path) -> None:
    """``--force simulate`` killed while simulate computes: the old output is still there,
    intact and unchanged; the next run removes the partial copy and has nothing to do. Fixed
    0.1 ms steps make simulate take seconds on the coarse mesh (adaptive steps took 0.8 s, as
    long as the wait before the kill)."""
    store = StageStore(ROOT / face_copy / "runs" / "store.zarr")
    slow = ["--set", "simulate.stepping=fixed", "--set", "simulate.dt=0.0001"]
    args = ["--dataset", str(face_copy), "-c", COARSE, *slow]
    assert invoke("run", *args, "--local").returncode == 0  # the latest run: this config's
    key = store.latest("simulate")
    before = store.provenance("simulate", key)["manifest"]
    proc = start("run", *args, "--local", "--force", "simulate")
    deadline = time.time() + 120
    while not list((store.root / TMP).glob("simulate-*")) and time.time() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()[0]
    time.sleep(random.Random(17).uniform(0.0, 1.5))
    proc.kill()
    out = proc.communicate()[0]
    assert list((store.root / TMP).glob("simulate-*")), "simulate finished before the kill: " + out
    assert store.has("simulate", key) and store.latest("simulate") == key
    assert store.provenance("simulate", key)["manifest"] == before
    assert_store_tells_the_truth(store)
    status = invoke("status", *args, "--json")
    assert status.returncode == 0 and '"action": "run"' not in status.stdout
    displacements = store.open("simulate", key)["displacements"][...]
    assert np.isfinite(displacements).all() and np.abs(displacements).max() > 0
