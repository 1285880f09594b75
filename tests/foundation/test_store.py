"""Atomicity of the stage store: SIGKILL mid-write, concurrent writers, keys, chunking."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import zarr

from physanim.store import StageStore, canonical_json, frame_chunks, stage_key
from physanim.store.stage_store import TMP

ROOT = Path(__file__).resolve().parents[2]
TOY = "tests.foundation.toy_stages:TOY"


def cli(*args: str, env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "cli", *args],
        cwd=ROOT,
        env={**os.environ, **env, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def test_sigkill_mid_write_leaves_nothing_complete_and_next_run_recomputes(
    toy_config: Path, tmp_path: Path
) -> None:
    store_root = tmp_path / "data" / "runs" / "store.zarr"
    env = {"PHYSANIM_TOY_LOG": str(tmp_path / "executions.log")}
    slow = ["-p", TOY, "-c", str(toy_config), "--set", "source.slow_s=0.1", "--local"]
    proc = cli("run", *slow, "--set", "source.n_frames=200", env=env)
    tmp_dir = store_root / TMP
    deadline = time.time() + 60
    # wait until the temporary output holds some chunks, then kill hard
    while time.time() < deadline:
        chunks = list(tmp_dir.glob("source-*/ramp/c/*")) if tmp_dir.exists() else []
        if len(chunks) >= 3:
            break
        time.sleep(0.05)
    else:
        proc.kill()
        pytest.fail("the toy stage never started writing: " + (proc.stdout.read() or ""))
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()

    store = StageStore(store_root)
    assert store.keys("source") == []  # nothing reads as complete
    assert store.latest("source") is None
    assert len(store.stale_temporaries()) == 1  # the dead writer's partial copy

    done = cli("run", *slow, "--set", "source.n_frames=20", env=env)
    out, _ = done.communicate(timeout=120)
    assert done.returncode == 0, out
    assert "removed abandoned partial output" in out
    assert list(tmp_dir.iterdir()) == []
    ramp = store.open("source")["ramp"][:]
    assert ramp.shape == (20, 1000)
    np.testing.assert_array_equal(ramp[:, 0], np.arange(20.0))


def test_two_processes_same_key_end_with_one_complete_copy(
    toy_config: Path, tmp_path: Path
) -> None:
    env = {"PHYSANIM_TOY_LOG": str(tmp_path / "executions.log")}
    args = ["run", "-p", TOY, "-c", str(toy_config), "--set", "source.slow_s=0.02", "--local"]
    procs = [cli(*args, env=env) for _ in range(2)]
    outs = [p.communicate(timeout=120)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    for stage in ("source", "scale", "total"):
        assert len(store.keys(stage)) == 1
    assert store.open("total")["total"][0] == pytest.approx(2 * (499500 * 8 + 1000 * 28))
    assert list((store.root / TMP).iterdir()) == []


def test_exception_in_stage_discards_output(tmp_path: Path) -> None:
    store = StageStore(tmp_path / "s.zarr")
    with pytest.raises(RuntimeError), store.writing("a", "k" * 64, {}) as g:
        g.create_array("x", shape=(3,), dtype="f4")
        raise RuntimeError("boom")
    assert store.keys("a") == [] and list((store.root / TMP).iterdir()) == []
    with store.writing("a", "k" * 64, {"version": "1"}) as g:
        g.create_array("x", shape=(3,), dtype="f4")[:] = 1.0
    meta = dict(zarr.open_group(store.root / "a" / ("k" * 64), mode="r").attrs)
    assert meta["complete"] is True and meta["version"] == "1" and meta["duration_s"] >= 0


def test_keys_are_canonical() -> None:
    a = stage_key("s", "1", {"b": 0.1, "a": [1, 2]}, {"up": "x"})
    b = stage_key("s", "1", {"a": [1, 2], "b": 1e-1}, {"up": "x"})
    assert a == b and len(a) == 64
    assert stage_key("s", "2", {"b": 0.1, "a": [1, 2]}, {"up": "x"}) != a
    assert stage_key("s", "1", {"b": 0.1, "a": [1, 2]}, {"up": "y"}) != a
    with pytest.raises(ValueError, match=r"^x\[1\]\.y: nan is not a finite number"):
        canonical_json({"x": [1.0, {"y": float("nan")}]})


def test_frame_chunks_split_frames_only() -> None:
    assert frame_chunks((90, 30000, 3), 4) == (11, 30000, 3)
    assert frame_chunks((90, 480, 640, 3), 1) == (4, 480, 640, 3)
    assert frame_chunks((5, 3000, 3000), 8) == (1, 3000, 3000)
    assert frame_chunks((7,), 8) == (7,)


def test_failing_stage_is_named_and_leaves_no_output(toy_config: Path, tmp_path: Path) -> None:
    env = {"PHYSANIM_TOY_LOG": str(tmp_path / "executions.log")}
    args = ["run", "-p", TOY, "-c", str(toy_config), "--local", "--set", "source.fail_at=3"]
    out, _ = cli(*args, env=env).communicate(timeout=120)
    assert "error: stage 'source' failed: ValueError: bad frame 3 (source.fail_at)" in out
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    assert store.keys("source") == [] and list((store.root / TMP).iterdir()) == []
