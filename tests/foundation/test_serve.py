"""Scheduled batch runs: `physanim serve` picks up a new dataset and exits cleanly on SIGTERM."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def wait_for(path: Path, seconds: float) -> bool:
    deadline = time.time() + seconds
    while time.time() < deadline:
        if path.exists():
            return True
        time.sleep(1.0)
    return False


def test_serve_processes_new_dataset_and_stops_on_signal(tmp_path: Path) -> None:
    datasets = tmp_path / "datasets"
    (datasets / "first").mkdir(parents=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    env.update(PYTHONPATH=str(ROOT), PHYSANIM_TOY_LOG=str(tmp_path / "executions.log"))
    cmd = [sys.executable, "-m", "cli", "serve", str(datasets)]
    cmd += ["-p", "tests.foundation.toy_stages:TOY", "--interval", "3"]
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    try:
        first = datasets / "first" / "runs" / "store.zarr" / "LATEST"
        assert wait_for(first, 240), "the first scheduled run never completed"
        (datasets / "second").mkdir()  # a new dataset dropped in while serving
        second = datasets / "second" / "runs" / "store.zarr" / "LATEST"
        assert wait_for(second, 120), "the new dataset was not processed"
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            out, _ = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            try:  # a process serve left behind would hold its output open for ever
                out, _ = proc.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                out = "(its output still held open by a process it left behind)"
            raise AssertionError(f"serve did not stop on SIGTERM:\n{out[-3000:]}") from None
    assert proc.returncode == 0, out[-3000:]
    assert "started Prefect server" in out and "stopped (server stopped)" in out
    assert (datasets / ".physanim" / "prefect").is_dir()  # Prefect home inside the folder


def test_a_scheduler_that_ignores_the_stop_is_killed_after_the_grace_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from cli import app

    monkeypatch.setattr(app, "SERVE_STOP_GRACE_S", 0.5)
    code = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(60)"
    child = subprocess.Popen([sys.executable, "-c", code])
    time.sleep(0.5)  # its handler is installed
    child.send_signal(signal.SIGINT)  # ignored, as a hung runner would
    t0 = time.monotonic()
    assert app._wait_or_kill(child, [t0]) == -signal.SIGKILL
    assert time.monotonic() - t0 < 10


def test_a_killed_scheduler_leaves_no_flow_run_behind(monkeypatch: pytest.MonkeyPatch) -> None:
    """The scheduler leads its own session; a process it started (a flow run, here one that
    ignores SIGINT and holds the output) is killed with it, not orphaned: an orphaned flow run
    waited for ever on the stopped server and held ``serve``'s output open."""
    from cli import app
    from physanim.processes import process_alive

    monkeypatch.setattr(app, "SERVE_STOP_GRACE_S", 0.5)
    flow_run = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(60)"
    code = (
        "import signal, subprocess, sys, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
        f"p = subprocess.Popen([sys.executable, '-c', {flow_run!r}]); print(p.pid, flush=True); "
        "time.sleep(60)"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, start_new_session=True
    )
    grandchild = int(child.stdout.readline())
    child.send_signal(signal.SIGINT)  # ignored by both
    assert app._wait_or_kill(child, [time.monotonic()]) == -signal.SIGKILL
    deadline = time.monotonic() + 10
    while process_alive(grandchild) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not process_alive(grandchild)
    assert child.stdout.read() == ""  # the pipe closed: nothing holds it open
