"""Hermetic Prefect settings: call ``configure`` before the first ``import prefect``.

Prefect keeps its profile, SQLite database and logs under ``PREFECT_HOME``; pointing it into the
run directory keeps runs (and tests) away from the user's own Prefect profile.  With no
``PREFECT_API_URL`` every flow run would start a temporary local API server (SQLite), whose
startup takes 10-25 s here; ``shared_server`` instead keeps one server per ``PREFECT_HOME``
running between runs (same database, so the UI shows every run) and stops it after
``PHYSANIM_PREFECT_IDLE_S`` seconds (default 600) without a run. ``start_shared_server`` begins
that start in the background, so that it overlaps other work (the demo's generation).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

from physanim.processes import OWNER_ENV, mark_children, process_alive, start_time

#: Seconds a shared server waits for the next run before it stops (``shared_server``).
IDLE_ENV = "PHYSANIM_PREFECT_IDLE_S"
_STATE, _LEASE, _LOCK, _STARTING = "server.json", "server.lease", "server.lock", "server.starting"
#: Times the supervisor starts ``prefect server start`` before it gives up (``_supervise``).
_ATTEMPTS = 3

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


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now (for a server started next)."""
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
    port = free_port()
    url = f"http://127.0.0.1:{port}/api"
    cmd, env = _server_command(home, port)
    log = (home / "server.log").open("w")
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.time() + startup_timeout
        while not _healthy(url):
            if proc.poll() is not None or time.time() > deadline:
                log.flush()
                why = (
                    "it exited"
                    if proc.poll() is not None
                    else f"no answer in {startup_timeout:.0f} s"
                )
                raise RuntimeError(_not_started(home, why))
            time.sleep(0.5)
        yield url, True
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()


def _server_command(home: Path, port: int) -> tuple[list[str], dict[str, str]]:
    env = {**os.environ, "PREFECT_HOME": str(home)}
    env.pop("PREFECT_API_URL", None)
    cmd = [sys.executable, "-m", "prefect", "server", "start", "--host", "127.0.0.1",
           "--port", str(port)]  # fmt: skip
    return cmd, env


def _live_record(path: Path) -> dict | None:
    """The JSON record ({"pid", "started", ...}) at ``path`` while the process it names still
    runs (same pid and start time); None otherwise."""
    try:
        state = json.loads(path.read_text())
        pid, started = int(state["pid"]), float(state["started"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    same = process_alive(pid) and abs((start_time(pid) or started) - started) < 2.0
    return state if same else None


def _running_shared(home: Path) -> str | None:
    """URL of the shared server of ``home`` when its supervisor runs and it answers."""
    state = _live_record(home / _STATE)
    url = None if state is None else str(state.get("url", ""))
    return url if url and _healthy(url) else None


def _starting(home: Path) -> bool:
    """True while a supervisor spawned for ``home`` runs (it may not answer yet)."""
    return _live_record(home / _STARTING) is not None


def _spawn_supervisor(home: Path) -> None:
    """Start ``python -m flows.prefect_env HOME`` detached (call with the home's lock held)."""
    env = {k: v for k, v in os.environ.items() if k != OWNER_ENV}
    proc = subprocess.Popen(
        [sys.executable, "-m", "flows.prefect_env", str(home)],
        env=env, cwd=Path(__file__).resolve().parents[1], start_new_session=True,
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    state = {"pid": proc.pid, "started": start_time(proc.pid) or time.time()}
    (home / _STARTING).write_text(json.dumps(state))


def start_shared_server(home: Path) -> None:
    """Begin starting the shared server of ``home`` (see ``shared_server``) and return at
    once; nothing when PREFECT_API_URL answers or the server runs or is starting already."""
    existing = os.environ.get("PREFECT_API_URL")
    if existing and _healthy(existing):
        return
    home = Path(home)
    home.mkdir(parents=True, exist_ok=True)
    with (home / _LOCK).open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        (home / _LEASE).touch()
        if _running_shared(home) is None and not _starting(home):
            _spawn_supervisor(home)


@contextlib.contextmanager
def shared_server(home: Path, startup_timeout: float = 120.0) -> Iterator[tuple[str, bool]]:
    """Yield (API URL, started_now) of the Prefect server shared by the runs of ``home``.

    PREFECT_API_URL wins when it answers. Otherwise the server that an earlier run of this
    home left running (or ``start_shared_server`` began to start) is used, or one is started:
    ``python -m flows.prefect_env HOME`` (a detached supervisor, not marked as this process's,
    so orphan clean-up leaves it alone) runs ``prefect server start`` and stops it, and
    itself, once no run has used it for PHYSANIM_PREFECT_IDLE_S seconds or when ``home`` is
    removed. While the caller runs, a thread renews the lease every few seconds.
    """
    existing = os.environ.get("PREFECT_API_URL")
    if existing and _healthy(existing):
        yield existing, False
        return
    home = Path(home)
    home.mkdir(parents=True, exist_ok=True)
    lease = home / _LEASE
    with (home / _LOCK).open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one starter per home at a time
        lease.touch()
        url, started = _running_shared(home), False
        if url is None:
            if not _starting(home):
                _spawn_supervisor(home)
            deadline = time.time() + startup_timeout
            while (url := _running_shared(home)) is None:
                if not _starting(home):
                    raise RuntimeError(_not_started(home, f"it exited {_ATTEMPTS} times"))
                if time.time() > deadline:
                    raise RuntimeError(_not_started(home, f"no answer in {startup_timeout:.0f} s"))
                time.sleep(0.25)
            started = True
    done = threading.Event()
    period = min(5.0, _idle_seconds() / 4)

    def renew() -> None:
        while not done.wait(period):
            with contextlib.suppress(OSError):
                lease.touch()

    keeper = threading.Thread(target=renew, name="prefect-lease", daemon=True)
    keeper.start()
    try:
        yield url, started
    finally:
        done.set()
        keeper.join()
        with contextlib.suppress(OSError):
            lease.touch()  # the idle time counts from the end of this run


def _not_started(home: Path, why: str) -> str:
    """The error for a shared server that did not start: why, and the end of its log."""
    log = home / "server.log"
    try:
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-15:])
    except OSError:
        tail = "(no log)"
    return f"prefect server did not start ({why}); the end of {log}:\n{tail}"


def _idle_seconds() -> float:
    return float(os.environ.get(IDLE_ENV, "600"))


def _supervise(home: Path) -> None:
    """Run a Prefect server for ``home`` until it is idle (see ``shared_server``).

    A server that exits before it answers is started again on a new port, up to
    ``_ATTEMPTS`` times: the port is only known free when it is picked, and the Dask cluster
    that a run starts meanwhile binds ports of the same ephemeral range. Every attempt's
    output goes to ``server.log``.
    """
    idle_s = _idle_seconds()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    state = home / _STATE
    proc: subprocess.Popen | None = None
    try:
        url = None
        with (home / "server.log").open("w") as log:
            for attempt in range(1, _ATTEMPTS + 1):
                port = free_port()
                log.write(f"--- physanim: prefect server start, attempt {attempt}, port {port}\n")
                log.flush()
                cmd, env = _server_command(home, port)
                proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
                candidate = f"http://127.0.0.1:{port}/api"
                while proc.poll() is None and not _healthy(candidate):
                    if stop.wait(0.25):
                        return
                if proc.poll() is None:
                    url = candidate
                    break
        if url is None:
            return
        tmp = home / f".{_STATE}.{os.getpid()}"
        me = os.getpid()
        tmp.write_text(json.dumps({"pid": me, "started": start_time(me) or 0.0, "url": url}))
        tmp.replace(state)
        ready = time.time()
        while not stop.wait(min(2.0, idle_s / 4)):
            try:
                quiet = time.time() - max((home / _LEASE).stat().st_mtime, ready)
            except OSError:  # home removed: nobody can use this server any more
                break
            if quiet > idle_s or proc.poll() is not None:
                break
    finally:
        with contextlib.suppress(OSError, ValueError):
            if json.loads(state.read_text()).get("pid") == os.getpid():
                state.unlink()
        if proc is not None:
            proc.terminate()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()


if __name__ == "__main__":
    _supervise(Path(sys.argv[1]))
