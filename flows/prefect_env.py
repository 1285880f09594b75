"""Hermetic Prefect settings: call ``configure`` before the first ``import prefect``.

Prefect keeps its profile, SQLite database and logs under ``PREFECT_HOME``; pointing it into the
run directory keeps runs (and tests) away from the user's own Prefect profile.  With no
``PREFECT_API_URL`` every flow run starts a temporary local API server (SQLite), which needs no
network; its startup takes 10-20 s here, so the default 20 s timeout is raised.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

from physanim.processes import mark_children

#: Settings applied unless the user already set them in the environment.
DEFAULTS = {
    "PREFECT_SERVER_ANALYTICS_ENABLED": "false",  # offline: telemetry only logs errors
    "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "120",
    "PREFECT_LOGGING_LEVEL": "WARNING",
    "PREFECT_RESULTS_PERSIST_BY_DEFAULT": "false",  # arrays live in the stage store
    "PREFECT_LOGGING_TO_API_ENABLED": "false",
    "DASK_LOGGING__DISTRIBUTED": "warning",  # Dask's per-worker INFO lines drown the progress
}


def configure(run_dir: Path) -> Path:
    """Set Prefect's home inside ``run_dir`` (unless PREFECT_HOME is set); returns the home.

    Also marks the processes started from now on (Prefect's temporary API server, Dask
    workers) as this process's, so that the next run stops them if this one is killed.
    """
    mark_children()
    if "prefect" in sys.modules:  # settings are read at import: too late to change them
        return Path(os.environ.get("PREFECT_HOME", "~/.prefect")).expanduser()
    home = Path(os.environ.setdefault("PREFECT_HOME", str(Path(run_dir).resolve() / "prefect")))
    home.mkdir(parents=True, exist_ok=True)
    for k, v in DEFAULTS.items():
        os.environ.setdefault(k, v)
    return home


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _healthy(api_url: str, timeout: float = 2.0) -> bool:
    try:
        with urllib.request.urlopen(f"{api_url.rstrip('/')}/health", timeout=timeout) as r:
            return r.status == 200
    except OSError:
        return False


@contextlib.contextmanager
def prefect_server(home: Path, startup_timeout: float = 120.0) -> Iterator[tuple[str, bool]]:
    """Yield (API URL, started_here): the server at PREFECT_API_URL when it answers, else a
    ``prefect server start`` on a free local port with its home in ``home``, stopped on exit.

    Needs no ``import prefect`` here, so the caller can set PREFECT_API_URL before importing it.
    """
    existing = os.environ.get("PREFECT_API_URL")
    if existing and _healthy(existing):
        yield existing, False
        return
    port = _free_port()
    url = f"http://127.0.0.1:{port}/api"
    env = {**os.environ, "PREFECT_HOME": str(home)}
    env.pop("PREFECT_API_URL", None)
    log = (home / "server.log").open("w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "prefect", "server", "start", "--host", "127.0.0.1",
         "--port", str(port)],
        env=env, stdout=log, stderr=subprocess.STDOUT,
    )  # fmt: skip
    try:
        deadline = time.time() + startup_timeout
        while not _healthy(url):
            if proc.poll() is not None or time.time() > deadline:
                raise RuntimeError(f"prefect server did not start; see {home / 'server.log'}")
            time.sleep(0.5)
        yield url, True
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
