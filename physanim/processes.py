"""Which process owns what: liveness of owner pids, and clean-up after killed physanim runs.

A physanim process marks the processes it starts (Prefect's temporary API server, Dask
workers, render workers) by putting ``PHYSANIM_OWNER=<pid>@<start>`` in their environment
(``<start>``: the owner's start in clock ticks since boot, exact and untouched by changes of
the wall clock, which a Unix start time computed from ``/proc/stat``'s boot time is not);
temporary folders carry the owner's pid in their name (``physanim-<what>-<pid>-<random>``).
When the owner was killed (SIGKILL leaves no chance to clean up), the next run finds these by
the owner's pid and stops or removes them.  Start times (Linux ``/proc``) guard against a
reused pid; elsewhere only ``kill(pid, 0)`` is checked.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import tempfile
import time
from pathlib import Path

#: Environment variable naming the physanim process that started a process (see module doc).
OWNER_ENV = "PHYSANIM_OWNER"
_TEMP_DIR = re.compile(r"^physanim-[a-z]+-(\d+)-")


def _boot_time() -> float:
    for line in Path("/proc/stat").read_text().splitlines():
        if line.startswith("btime "):
            return float(line.split()[1])
    raise OSError("no btime in /proc/stat")


def _stat_fields(pid: int) -> list[str] | None:
    """Fields of /proc/<pid>/stat after the command name, or None if there is no such file."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text.rsplit(")", 1)[1].split()


def start_time(pid: int) -> float | None:
    """Unix time (s) at which process ``pid`` started; None when unknown or not running."""
    fields = _stat_fields(pid)
    if fields is None:
        return None
    try:
        return _boot_time() + int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def process_alive(pid: int, started_before: float | None = None) -> bool:
    """True when ``pid`` runs (not a zombie) and, if given, started before that Unix time (s).

    A process that started later than ``started_before`` cannot have made something created
    then: its pid was reused.
    """
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    fields = _stat_fields(pid)
    if fields is None:
        return not Path("/proc/self/stat").exists()  # no /proc: trust kill(0)
    if fields[0] in ("Z", "X"):  # zombie / dead: exited, only waiting to be reaped
        return False
    if started_before is not None:
        started = start_time(pid)
        if started is not None and started > started_before + 1.0:  # 1 s: tick rounding
            return False
    return True


def start_ticks(pid: int) -> int | None:
    """Start of process ``pid`` in clock ticks since boot (exact); None when not running."""
    fields = _stat_fields(pid)
    try:
        return int(fields[19]) if fields is not None else None
    except (ValueError, IndexError):
        return None


def owner_token(pid: int | None = None) -> str:
    """``<pid>@<start ticks>`` of a process (default: this one), the value of OWNER_ENV."""
    pid = os.getpid() if pid is None else pid
    started = start_ticks(pid)
    return f"{pid}@{started}" if started is not None else str(pid)


def owner_alive(token: str) -> bool:
    """True when the process named by an OWNER_ENV token still runs (same pid and start)."""
    pid_text, _, started = token.partition("@")
    try:
        pid = int(pid_text)
    except ValueError:
        return False
    if not process_alive(pid):
        return False
    now = start_ticks(pid)
    return not started.isdigit() or now is None or now == int(started)


def mark_children() -> None:
    """Mark the processes this one starts from now on as its own (sets OWNER_ENV)."""
    os.environ[OWNER_ENV] = owner_token()


def _orphans() -> list[tuple[int, str, str]]:
    """(pid, owner token, command line) of this user's processes whose owner is gone."""
    found = []
    me = os.getuid()
    for entry in Path("/proc").iterdir() if Path("/proc").is_dir() else []:
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if entry.stat().st_uid != me:
                continue
            env = (entry / "environ").read_bytes().split(b"\0")
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        prefix = OWNER_ENV.encode() + b"="
        token = next((e[len(prefix) :].decode() for e in env if e.startswith(prefix)), None)
        fields = _stat_fields(int(entry.name))
        parent = fields[1] if fields is not None else None  # the field after the state
        if token is None or parent == token.partition("@")[0]:
            continue  # not marked, or its owner is its parent: that one still runs
        if not owner_alive(token) and process_alive(int(entry.name)):
            found.append((int(entry.name), token, cmd.strip()))
    return found


def stop_orphans(grace_s: float = 5.0) -> list[str]:
    """Stop (SIGTERM, then SIGKILL after ``grace_s``) processes a killed physanim left
    running, e.g. Prefect's temporary API server; returns one line per process stopped."""
    orphans = _orphans()
    for pid, _, _ in orphans:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGTERM)
    deadline = time.time() + grace_s
    for pid, _, _ in orphans:
        while process_alive(pid) and time.time() < deadline:
            time.sleep(0.05)
        if process_alive(pid):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
    return [
        f"stopped process {pid} ({cmd[:80]}) left running by a killed physanim "
        f"(pid {token.partition('@')[0]})"
        for pid, token, cmd in orphans
    ]


def remove_stale_temp_dirs(parent: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove ``physanim-<what>-<pid>-*`` folders (default: in the system temporary
    directory) whose owner pid no longer runs; returns the removed paths."""
    root = Path(parent or tempfile.gettempdir())
    removed = []
    for p in root.iterdir() if root.is_dir() else []:
        m = _TEMP_DIR.match(p.name)
        if not m or not p.is_dir():
            continue
        try:
            made = p.stat().st_mtime
        except OSError:
            continue
        if not process_alive(int(m.group(1)), started_before=made):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed
