"""One Prefect server per PREFECT_HOME shared by consecutive runs, stopped when idle."""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import pytest

from flows.prefect_env import IDLE_ENV, shared_server, start_shared_server
from physanim.processes import OWNER_ENV, _orphans, mark_children, process_alive


def test_runs_share_one_server_that_stops_when_idle(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    home = tmp_path / "prefect"
    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    monkeypatch.setenv(IDLE_ENV, "4")
    mark_children()  # as the CLI does: the server must not count as this process's child
    start_shared_server(home)  # as a run does before it generates the demo: returns at once
    starting = json.loads((home / "server.starting").read_text())["pid"]
    start_shared_server(home)  # no second server while the first one starts
    assert json.loads((home / "server.starting").read_text())["pid"] == starting
    with shared_server(home) as (url, started):
        assert started
        pid = json.loads((home / "server.json").read_text())["pid"]
        assert pid == starting  # the run waited for the server started before it
        assert OWNER_ENV not in Path(f"/proc/{pid}/environ").read_text()
        time.sleep(6)  # longer than the idle time: the open run's lease keeps it alive
        with shared_server(home) as (again, started_again):
            assert (again, started_again) == (url, False)  # reused, not restarted
    assert pid not in [p for p, _, _ in _orphans()]  # orphan clean-up leaves it alone
    deadline = time.time() + 60
    while process_alive(pid) and time.time() < deadline:
        time.sleep(0.5)
    assert not process_alive(pid)  # stopped after the idle time
    assert not (home / "server.json").exists()
    assert (home / "prefect.db").exists()  # the run history stays
    os.environ.pop(OWNER_ENV, None)


def test_a_server_that_cannot_start_is_retried_then_explained(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    home = tmp_path / "prefect"
    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    # a database Prefect cannot open: every `prefect server start` exits during its startup
    bad = f"sqlite+aiosqlite:///{tmp_path / 'missing' / 'prefect.db'}"
    monkeypatch.setenv("PREFECT_API_DATABASE_CONNECTION_URL", bad)
    t0 = time.time()
    with pytest.raises(RuntimeError) as err, shared_server(home, startup_timeout=300):
        pass
    assert time.time() - t0 < 200  # told as soon as the last attempt exits, not at the timeout
    message = str(err.value)
    assert "prefect server did not start (it exited 3 times)" in message
    assert "unable to open database file" in message  # the end of the server's own log
    log = (home / "server.log").read_text()
    assert [int(n) for n in re.findall(r"attempt (\d), port", log)] == [1, 2, 3]
    assert not (home / "server.json").exists()
