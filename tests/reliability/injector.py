"""File-system faults for the reliability campaign, injected in Python below the store.

``python -m tests.reliability.injector ARGS`` runs ``physanim ARGS`` with faults installed
from the environment (the campaign starts its faulty runs this way):

- ``PHYSANIM_INJECT=enospc:N``: the N-th write to a file under ``PHYSANIM_INJECT_ROOT`` writes
  half its data and fails with ENOSPC, and so do every later write and ``mkdir`` there (the
  disk stays full until the process ends);
- ``PHYSANIM_INJECT=eio:N``: the N-th write fails with EIO after half its data (one bad
  write; the next ones succeed);
- ``PHYSANIM_INJECT=rename:N``: the N-th ``os.rename``/``os.replace`` of a path under the
  root fails with EIO (a commit, Zarr's own atomic chunk write, a run manifest...);
- ``PHYSANIM_INJECT=kill:N``: at the N-th write or rename under the root the process kills
  itself with SIGKILL (after half the write, or just after the rename): kill -9 at a chosen
  point inside a stage's write, its commit or the run manifest;
- ``PHYSANIM_INJECT=count:0``: nothing fails; the numbers of writes and renames seen are
  written as JSON to ``PHYSANIM_INJECT_REPORT`` at exit (how many points a fault can hit).

Writes are counted per call of ``write`` on files opened for writing through ``open`` /
``io.open`` / ``Path.open`` (Zarr's LocalStore, ``Path.write_text``...), from any thread.
The errors carry no file name, as the kernel's do not.  ``inject`` installs the same faults
in this process (a context manager, for tests).
"""

from __future__ import annotations

import atexit
import builtins
import contextlib
import errno
import io
import json
import os
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

KINDS = ("enospc", "eio", "rename", "kill", "count")
#: what ``Faults.write_fails`` returns for a write that kills the process
KILL = -1


class Faults:
    """The fault plan of one process and what it has seen so far."""

    def __init__(self, kind: str, n: int, root: str | os.PathLike[str]) -> None:
        if kind not in KINDS:
            raise ValueError(f"unknown fault kind {kind!r}; one of {', '.join(KINDS)}")
        self.kind, self.n, self.root = kind, n, os.path.realpath(root)
        self.writes = self.renames = 0
        #: writes and renames by the stage whose temporary output they touch ("" for the rest:
        #: group metadata, run manifests, LATEST)
        self.by_stage: dict[str, list[int]] = {}
        self.fired: str | None = None  # what failed first, for the campaign's log
        self._lock = threading.Lock()

    def covers(self, path: Any) -> bool:
        if isinstance(path, int):
            return False
        try:
            full = os.path.realpath(os.fspath(path))
        except TypeError:
            return False
        return full == self.root or full.startswith(self.root + os.sep)

    def _tally(self, path: str, which: int) -> None:
        parts = os.path.relpath(os.path.realpath(path), self.root).split(os.sep)
        stage = parts[1].split("-")[0] if parts[0] == ".tmp" and len(parts) > 1 else ""
        self.by_stage.setdefault(stage, [0, 0])[which] += 1

    def write_fails(self, path: str) -> int | None:
        """errno the next write to ``path`` fails with, KILL, or None."""
        with self._lock:
            self.writes += 1
            self._tally(path, 0)
            if self.kind == "kill" and self.writes + self.renames == self.n:
                return KILL
            if self.kind == "enospc" and (self.fired or self.writes == self.n):
                self.fired = self.fired or f"write {self.writes} to {path}"
                return errno.ENOSPC
            if self.kind == "eio" and self.writes == self.n:
                self.fired = f"write {self.writes} to {path}"
                return errno.EIO
        return None

    def mkdir_fails(self) -> bool:
        return self.kind == "enospc" and self.fired is not None

    def rename_fails(self, src: str) -> bool:
        with self._lock:
            self.renames += 1
            self._tally(src, 1)
            if self.kind == "kill" and self.writes + self.renames == self.n:
                self.fired = "kill"
                return True
            if self.kind == "rename" and self.renames == self.n:
                self.fired = f"rename {self.renames} of {src}"
                return True
        return False

    def report(self) -> dict[str, Any]:
        return {
            "writes": self.writes,
            "renames": self.renames,
            "by_stage": self.by_stage,
            "fired": self.fired,
        }


class _FaultyFile:
    """A file opened for writing whose ``write`` may fail as ``Faults`` decides."""

    def __init__(self, f: Any, faults: Faults, path: str) -> None:
        self._f, self._faults, self._path = f, faults, path

    def write(self, data: Any) -> int:
        code = self._faults.write_fails(self._path)
        if code is None:
            return self._f.write(data)
        if isinstance(data, str):
            self._f.write(data[: len(data) // 2])
        else:
            view = memoryview(data).cast("B")
            self._f.write(view[: len(view) // 2])
        self._f.flush()  # the half that fitted reaches the file, as on a real disk
        if code == KILL:
            os.kill(os.getpid(), signal.SIGKILL)
        raise OSError(code, os.strerror(code))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._f, name)

    def __enter__(self) -> _FaultyFile:
        self._f.__enter__()
        return self

    def __exit__(self, *exc: object) -> Any:
        return self._f.__exit__(*exc)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._f)


_installed: list[tuple[Any, Any, Any, Any]] = []


def install(faults: Faults) -> None:
    """Wrap ``open``, ``os.mkdir``, ``os.rename`` and ``os.replace`` of this process."""
    real_open, real_mkdir, real_rename, real_replace = io.open, os.mkdir, os.rename, os.replace

    def faulty_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        f = real_open(file, mode, *args, **kwargs)
        if any(c in mode for c in "wax+") and faults.covers(file):
            return _FaultyFile(f, faults, os.fspath(file))
        return f

    def faulty_mkdir(path: Any, *args: Any, **kwargs: Any) -> None:
        if faults.mkdir_fails() and faults.covers(path):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), os.fspath(path))
        real_mkdir(path, *args, **kwargs)

    def move(real: Any) -> Any:
        def faulty(src: Any, dst: Any, *args: Any, **kwargs: Any) -> None:
            if faults.covers(src) and faults.rename_fails(os.fspath(src)):
                if faults.kind != "kill":
                    raise OSError(errno.EIO, os.strerror(errno.EIO), os.fspath(src))
                real(src, dst, *args, **kwargs)
                os.kill(os.getpid(), signal.SIGKILL)
            real(src, dst, *args, **kwargs)

        return faulty

    _installed.append((real_open, real_mkdir, real_rename, real_replace))
    io.open = builtins.open = faulty_open  # type: ignore[assignment]
    os.mkdir = faulty_mkdir  # type: ignore[assignment]
    os.rename, os.replace = move(real_rename), move(real_replace)


def uninstall() -> None:
    """Undo the last ``install``."""
    real_open, real_mkdir, real_rename, real_replace = _installed.pop()
    io.open = builtins.open = real_open
    os.mkdir, os.rename, os.replace = real_mkdir, real_rename, real_replace


@contextlib.contextmanager
def inject(kind: str, n: int, root: str | os.PathLike[str]) -> Iterator[Faults]:
    """Faults installed in this process for the duration of the block."""
    faults = Faults(kind, n, root)
    install(faults)
    try:
        yield faults
    finally:
        uninstall()


def from_environment() -> Faults | None:
    """Install the faults ``PHYSANIM_INJECT`` asks for (None when it is unset)."""
    spec = os.environ.get("PHYSANIM_INJECT")
    if not spec:
        return None
    kind, _, n = spec.partition(":")
    faults = Faults(kind, int(n or 0), os.environ["PHYSANIM_INJECT_ROOT"])
    install(faults)
    report = os.environ.get("PHYSANIM_INJECT_REPORT")
    if report:
        atexit.register(lambda: Path(report).write_text(json.dumps(faults.report())))
    return faults


def main() -> None:
    from_environment()
    from cli.app import main as physanim

    sys.argv = ["physanim", *sys.argv[1:]]
    physanim()


if __name__ == "__main__":
    main()
