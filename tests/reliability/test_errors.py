"""User errors are one line naming the file, key or option and the fix; what killed runs
leave behind (servers, temporary folders, partial outputs) is cleaned up by the next run."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from typer.testing import CliRunner

from cli.app import app
from physanim.processes import (
    OWNER_ENV,
    _orphans,
    owner_alive,
    owner_token,
    process_alive,
    start_time,
)
from physanim.store import StageStore
from physanim.store.stage_store import TMP
from tests.commands import ROOT, TOY, physanim


def one_error(args: list[str], code: int = 2) -> str:
    """Run the CLI in-process; the one-line error it printed (no traceback)."""
    result = CliRunner().invoke(app, args)
    assert result.exit_code == code, result.output
    assert isinstance(result.exception, SystemExit | None), result.exception
    lines = [x for x in result.output.splitlines() if x.strip()]
    assert lines[0].startswith("error: "), result.output
    return result.output


def test_user_errors_are_one_clear_line(toy_config: Path, tmp_path: Path) -> None:
    toy = ["-p", TOY, "-c", str(toy_config)]
    out = one_error(["status", *toy, "--set", "source.slow_s=.inf"])
    assert "--set source.slow_s=.inf: source.slow_s: must be a finite number (got inf)" in out
    out = one_error(["status", *toy, "--set", "scale.factor=[nose]"])
    assert "--set scale.factor=[nose]: scale.factor: Input should be a valid number" in out
    out = one_error(["show", "nosuch", *toy])
    assert out == ("error: pipeline 'toy' has no stage 'nosuch'; stages: source, scale, total\n")
    out = one_error(["status", "-p", "os:path"])
    assert out == "error: -p os:path: 'path' is a module, not a physanim.pipeline.Pipeline\n"
    out = one_error(["status", "-p", "nosuch_module:DAG"])
    assert "-p nosuch_module:DAG: cannot import 'nosuch_module'" in out
    sweep = tmp_path / "bad.yaml"
    sweep.write_text(
        f"pipeline: {TOY}\ndatasets: [{tmp_path / 'data'}]\n"
        "variants: [{name: ok, set: {scale.factor: 2}}, {name: bad, set: {scale.factor: -1}}]\n"
    )
    out = one_error(["sweep", str(sweep), "--serial"])
    assert f"{sweep}: variant 'bad': invalid config:" in out and "scale.factor: must be > 0" in out
    # a dataset directory that does not exist is reported, never created
    missing = tmp_path / "nosuch"
    result = CliRunner().invoke(app, ["status", *toy, "--dataset", str(missing)])
    assert result.exit_code == 0 and f"dataset directory {missing} does not exist" in result.output
    assert not missing.exists()


def test_the_next_run_stops_orphans_and_removes_temporary_folders(
    toy_config: Path, tmp_path: Path
) -> None:
    """A killed physanim leaves a child running (as Prefect's API server was) and a render
    folder in the system's temporary directory: the next ``run`` stops and removes them."""
    owner_code = (
        "import subprocess, sys, time\n"
        "from physanim.processes import mark_children\n"
        "mark_children()\n"
        "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])\n"
        "print(child.pid, flush=True)\n"
        "time.sleep(120)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    owner = subprocess.Popen([sys.executable, "-c", owner_code], env=env, stdout=subprocess.PIPE,
                             text=True)  # fmt: skip
    child = int(owner.stdout.readline())
    owner.kill()
    owner.wait()
    assert process_alive(child)  # orphaned
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    temp = Path(tempfile.gettempdir())
    stale = temp / f"physanim-render-{gone.pid}-test16"
    live = temp / f"physanim-render-{os.getpid()}-test16"
    for folder in (stale, live):
        folder.mkdir()
        (folder / "frames.npy").write_bytes(bytes(1000))
    try:
        out = physanim("run", "-p", TOY, "-c", str(toy_config), "--local")
        assert out.returncode == 0, out.stderr
        assert f"stopped process {child} " in out.stderr
        assert f"removed {stale}, left behind by a killed physanim" in out.stderr
        deadline = time.time() + 10
        while process_alive(child) and time.time() < deadline:
            time.sleep(0.05)
        assert not process_alive(child) and not stale.exists() and live.exists()
    finally:
        for folder in (stale, live):
            if folder.exists():
                (folder / "frames.npy").unlink()
                folder.rmdir()
        if process_alive(child):
            os.kill(child, signal.SIGKILL)


def test_a_run_whose_owner_runs_is_no_orphan() -> None:
    """The owner token names the start in clock ticks (a wall-clock step cannot make a live
    owner look dead), and a marked process whose parent is its owner is never stopped, even
    when the token's start does not match (a CI failure: a run stopped its sibling runs)."""
    assert owner_alive(owner_token())
    assert not owner_alive(f"{os.getpid()}@{int(owner_token().partition('@')[2]) + 100}")
    env = {**os.environ, OWNER_ENV: f"{os.getpid()}@1"}  # this process, a wrong start
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"], env=env)
    try:
        time.sleep(0.3)
        assert child.pid not in [pid for pid, _, _ in _orphans()]
    finally:
        child.kill()
        child.wait()


def test_a_zombie_or_reused_pid_does_not_keep_a_partial_output(tmp_path: Path) -> None:
    store = StageStore(tmp_path / "store.zarr")
    zombie = subprocess.Popen([sys.executable, "-c", "pass"])  # exits, not reaped: a zombie
    try:
        deadline = time.time() + 30
        while process_alive(zombie.pid) and time.time() < deadline:
            time.sleep(0.05)
        host = socket.gethostname()
        dead = store.root / TMP / f"source-{'0' * 16}-{host}-{zombie.pid}-0000dead"
        mine = store.root / TMP / f"source-{'1' * 16}-{host}-{os.getpid()}-0000live"
        for p in (dead, mine):
            p.mkdir()
        assert store.stale_temporaries() == [dead]
        # a pid that runs now but started after the partial output was written: reused
        before_me = start_time(os.getpid()) - 60
        os.utime(mine, (before_me, before_me))
        assert sorted(store.stale_temporaries()) == sorted([dead, mine])
    finally:
        zombie.wait()
