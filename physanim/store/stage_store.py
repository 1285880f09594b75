"""Content-addressed Zarr v3 store of stage outputs.

Layout of one store (a local directory, Zarr ``LocalStore``)::

    store.zarr/
      zarr.json                 root group
      <stage>/zarr.json         one group per stage
      <stage>/<key>/...         one complete output (group with arrays and provenance attrs)
      <stage>/LATEST            text file: key of the default output of the stage
      .tmp/<stage>-<key>-...    outputs being written (invisible to readers)

An output is written in ``.tmp/`` and moved into ``<stage>/<key>`` by one ``os.rename`` only
after its ``complete`` attribute is set, so a process killed at any moment never leaves a group
that reads as complete; Zarr v3 would otherwise read missing chunks of a half-written array as
fill values without error.  When two writers race on the same key, the first rename wins and the
other discards its copy (renaming onto a non-empty directory fails atomically on POSIX).
Atomic rename is why the store must be a local (or POSIX-shared, e.g. NFS) directory.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import json
import os
import shutil
import socket
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import zarr

import physanim

T = TypeVar("T")

TMP = ".tmp"
LATEST = "LATEST"
#: Target size of one chunk, bytes; arrays are chunked along their first (frame) axis only.
CHUNK_BYTES = 4 * 2**20
#: Age after which a temporary output of another host is considered abandoned, seconds.
STALE_FOREIGN_S = 24 * 3600


class StageOutputMissing(LookupError):
    """No complete output exists for the requested stage and key."""


def frame_chunks(shape: tuple[int, ...], itemsize: int) -> tuple[int, ...]:
    """Chunk shape that splits only the first axis, about CHUNK_BYTES per chunk, >= 1 frame."""
    if not shape:
        return ()
    per_frame = itemsize * int(np.prod(shape[1:], dtype=np.int64))
    n = max(1, min(shape[0], CHUNK_BYTES // max(per_frame, 1)))
    return (n, *shape[1:])


def write_array(group: zarr.Group, name: str, data: np.ndarray) -> zarr.Array:
    """Write ``data`` as array ``name`` of ``group``, chunked by frames (first axis)."""
    data = np.asarray(data)
    chunks = frame_chunks(data.shape, data.dtype.itemsize) if data.ndim else ()
    arr = group.create_array(name, shape=data.shape, dtype=data.dtype, chunks=chunks or "auto")
    arr[...] = data
    return arr


def write_dataclass(group: zarr.Group, record: object, prefix: str = "") -> None:
    """Write each numpy-array field of dataclass ``record`` as ``<prefix>/<field>``.

    Scalar fields (numbers, strings, bools, lists of them) go to the group's attributes.
    """
    target = group.require_group(prefix) if prefix else group
    for f in dataclasses.fields(record):  # type: ignore[arg-type]
        value = getattr(record, f.name)
        if isinstance(value, np.ndarray):
            write_array(target, f.name, value)
        elif isinstance(value, str | int | float | bool | list | tuple | dict) or value is None:
            target.attrs[f.name] = value
        else:
            raise TypeError(f"cannot store field {f.name!r} of type {type(value).__name__}")


def read_dataclass(cls: type[T], group: zarr.Group) -> T:
    """Rebuild a dataclass written by ``write_dataclass`` from its group."""
    kwargs = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        kwargs[f.name] = group[f.name][...] if f.name in group else group.attrs[f.name]
    return cls(**kwargs)


def _ensure_group(path: Path) -> None:
    """Make ``path`` an (empty) Zarr v3 group if it is not one; safe when processes race.

    The metadata is written to a temporary file and renamed into place, so a concurrent
    reader never sees a half-written zarr.json (Zarr's own writer gives no such guarantee).
    """
    meta = path / "zarr.json"
    if meta.exists():
        return
    path.mkdir(parents=True, exist_ok=True)
    tmp = path / f".zarr.json.{uuid.uuid4().hex}"
    tmp.write_text(json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {}}))
    os.replace(tmp, meta)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class StageStore:
    """One Zarr store of stage outputs, addressed by (stage name, content key)."""

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)
        _ensure_group(self.root)
        (self.root / TMP).mkdir(exist_ok=True)

    # -- reading ---------------------------------------------------------------------------
    def _path(self, stage: str, key: str) -> Path:
        return self.root / stage / key

    def files(self, stage: str, key: str) -> Path:
        """Directory of the plain files (PNG, MP4) of an output; absent if it wrote none."""
        return self._path(stage, key).resolve() / "files"

    def has(self, stage: str, key: str) -> bool:
        """True when a complete output of ``stage`` with ``key`` exists."""
        meta = self._path(stage, key) / "zarr.json"
        if not meta.exists():
            return False
        attrs = json.loads(meta.read_text()).get("attributes", {})
        return bool(attrs.get("complete"))

    def open(self, stage: str, key: str | None = None) -> zarr.Group:
        """Open a complete output read-only (``key=None``: the stage's latest)."""
        if key is None:
            key = self.latest(stage)
            if key is None:
                raise StageOutputMissing(f"stage '{stage}' has no output in {self.root}")
        if not self.has(stage, key):
            raise StageOutputMissing(
                f"no complete output of stage '{stage}' with key {key[:12]} in {self.root}"
            )
        return zarr.open_group(self._path(stage, key), mode="r")

    def provenance(self, stage: str, key: str | None = None) -> dict[str, Any]:
        """Provenance attributes of a complete output (``key=None``: the latest)."""
        return dict(self.open(stage, key).attrs)

    def keys(self, stage: str) -> list[str]:
        """Keys of all complete outputs of ``stage``, oldest first."""
        d = self.root / stage
        if not d.is_dir():
            return []
        found = [p.name for p in d.iterdir() if p.is_dir() and self.has(stage, p.name)]
        return sorted(found, key=lambda k: (self._path(stage, k) / "zarr.json").stat().st_mtime)

    def stages(self) -> list[str]:
        """Names of stages that have a group in the store."""
        return sorted(
            p.name for p in self.root.iterdir() if p.is_dir() and (p / "zarr.json").exists()
        )

    def latest(self, stage: str) -> str | None:
        """Key of the stage's default output, or None."""
        p = self.root / stage / LATEST
        if not p.exists():
            return None
        key = p.read_text().strip()
        return key if self.has(stage, key) else None

    def set_latest(self, stage: str, key: str) -> None:
        """Point the stage's default output at ``key`` (atomic replace of the pointer file)."""
        if not self.has(stage, key):
            raise StageOutputMissing(f"cannot point '{stage}' at missing key {key[:12]}")
        if self.latest(stage) == key:
            return  # unchanged: keep the pointer's mtime (reports compare against it)
        tmp = self.root / stage / f".{LATEST}.{uuid.uuid4().hex}"
        tmp.write_text(key + "\n")
        os.replace(tmp, self.root / stage / LATEST)

    # -- writing ---------------------------------------------------------------------------

    @contextlib.contextmanager
    def writing(self, stage: str, key: str, provenance: dict[str, Any]) -> Iterator[zarr.Group]:
        """Write one output atomically: yields a fresh group; commits it on normal exit.

        On an exception the temporary copy is removed and the exception propagates.  If another
        writer committed the same key meanwhile, this copy is discarded (same content key).
        """
        _ensure_group(self.root / stage)
        host = socket.gethostname()
        tmp = self.root / TMP / f"{stage}-{key[:16]}-{host}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        t0 = time.time()
        group = zarr.open_group(tmp, mode="w")
        group.attrs.update(
            {
                **provenance,
                "stage": stage,
                "key": key,
                "physanim_version": physanim.__version__,
                "host": host,
                "started": dt.datetime.fromtimestamp(t0, dt.UTC).isoformat(),
                "complete": False,
            }
        )
        try:
            yield group
            t1 = time.time()
            group.attrs.update(
                {
                    "finished": dt.datetime.fromtimestamp(t1, dt.UTC).isoformat(),
                    "duration_s": round(t1 - t0, 6),
                }
            )
            group.attrs["complete"] = True  # last write before the rename
            try:
                os.rename(tmp, self._path(stage, key))
            except OSError:
                if not self.has(stage, key):
                    raise
                shutil.rmtree(tmp, ignore_errors=True)  # another writer won the race
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise

    # -- housekeeping ----------------------------------------------------------------------
    def stale_temporaries(self) -> list[Path]:
        """Temporary outputs whose writer is gone (dead local pid, or old foreign host)."""
        host = socket.gethostname()
        stale = []
        for p in (self.root / TMP).iterdir():
            parts = p.name.split("-")
            if parts[0] == "trash":
                stale.append(p)
                continue
            try:
                owner, pid = "-".join(parts[2:-2]), int(parts[-2])
            except (ValueError, IndexError):
                stale.append(p)
                continue
            if owner == host:
                if not _pid_alive(pid):
                    stale.append(p)
            elif time.time() - p.stat().st_mtime > STALE_FOREIGN_S:
                stale.append(p)
        return stale

    def remove_stale_temporaries(self) -> list[Path]:
        """Delete abandoned temporary outputs; returns what was removed."""
        stale = self.stale_temporaries()
        for p in stale:
            shutil.rmtree(p, ignore_errors=True)
        return stale

    def unreachable(self, keep: set[tuple[str, str]]) -> list[tuple[str, str]]:
        """Complete outputs not in ``keep`` and not any stage's latest."""
        out = []
        for stage in self.stages():
            latest = self.latest(stage)
            out += [(stage, k) for k in self.keys(stage) if (stage, k) not in keep and k != latest]
        return out

    def remove(self, stage: str, key: str) -> None:
        """Delete one output (renamed into .tmp first, so it vanishes atomically for readers)."""
        trash = self.root / TMP / f"trash-{stage}-{key[:16]}-{uuid.uuid4().hex[:8]}"
        os.rename(self._path(stage, key), trash)
        shutil.rmtree(trash)
