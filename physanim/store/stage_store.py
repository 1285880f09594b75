"""Content-addressed Zarr v3 store of stage outputs: the ``StageStore`` class (opening a store,
reading outputs, the atomic ``writing`` commit), composed with ``runs`` (run manifests,
``LATEST``) and ``integrity`` (manifests, damage, quarantine, temporaries); ``codec`` maps
dataclasses to the groups inside one output.

Layout of one store (a local directory, Zarr ``LocalStore``)::

    store.zarr/
      zarr.json                 root group
      <stage>/zarr.json         one group per stage
      <stage>/<key>/...         one complete output (group with arrays and provenance attrs)
      .runs/<time>-<id>.json    run manifests: the stage keys of one run, written atomically
      LATEST                    text file: name of the latest run's manifest
      .tmp/<stage>-<key>-...    outputs being written (invisible to readers)
      .quarantine/...           damaged outputs moved aside, with the reason beside them

An output is written in ``.tmp/`` and moved into ``<stage>/<key>`` by one ``os.rename`` only
after its ``complete`` attribute is set, so a process killed at any moment never leaves a group
that reads as complete; Zarr v3 would otherwise read missing chunks of a half-written array as
fill values without error.  The same last metadata write records the output's manifest: the
size and SHA-256 of every file of the group (array metadata, chunks, plain files), and the
SHA-256 of that metadata document itself (``metadata_sha256``).  Every read
through the store checks that those files are present with their sizes (cheap), ``verify``
also checks their checksums, so a deleted or truncated chunk is an error naming stage, key,
array and chunk instead of zeros.  A damaged or incomplete group found at a final path is moved
to ``.quarantine/`` and recomputed.  When two writers race on the same key, the first rename
wins and the other discards its copy (renaming onto a non-empty directory fails atomically on
POSIX); a forced recomputation replaces the old output only once the new one is complete.
Atomic rename is why the store must be a local (or POSIX-shared, e.g. NFS) directory.

Each run records the keys it used in one run manifest, and ``LATEST`` names the manifest of
the latest run, so concurrent runs each leave a coherent set of outputs; the latest output of a
stage is its key in the latest run manifest that has it.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import logging
import os
import shutil
import socket
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import zarr

import physanim
from physanim.store.integrity import (
    QUARANTINE,
    TMP,
    StoreIntegrity,
    build_manifest,
    discard,
    ensure_group,
    seal_metadata,
)
from physanim.store.runs import LATEST, RUNS, StoreRuns

#: Names other modules import from here (the layout's directory names, the manifest builder).
__all__ = [
    "LATEST",
    "QUARANTINE",
    "RUNS",
    "TMP",
    "StageOutputDamaged",
    "StageOutputMissing",
    "StageStore",
    "build_manifest",
]

log = logging.getLogger(__name__)


class StageOutputMissing(LookupError):
    """No complete output exists for the requested stage and key."""


class StageOutputDamaged(StageOutputMissing):
    """An output exists at its final path but is damaged (missing or altered files, unreadable
    or incomplete metadata); the message names stage, key, array and chunk."""


class StageStore(StoreRuns, StoreIntegrity):
    """One Zarr store of stage outputs, addressed by (stage name, content key).

    ``create=False`` opens a store for reading only: nothing is created (``status``, ``show``
    and ``verify`` must not create a store or a dataset directory that does not exist).
    """

    def __init__(self, root: str | os.PathLike[str], *, create: bool = True) -> None:
        self.root = Path(root)
        self._host = socket.gethostname()
        if create:
            if not (self.root / "zarr.json").exists():  # a new store records runs from the start
                (self.root / RUNS).mkdir(parents=True, exist_ok=True)
            ensure_group(self.root)
            (self.root / TMP).mkdir(exist_ok=True)

    # -- reading ---------------------------------------------------------------------------
    def _path(self, stage: str, key: str) -> Path:
        return self.root / stage / key

    def files(self, stage: str, key: str) -> Path:
        """Directory of the plain files (PNG, MP4) of an output; absent if it wrote none."""
        return self._path(stage, key).resolve() / "files"

    def has(self, stage: str, key: str) -> bool:
        """True when a complete, intact output of ``stage`` with ``key`` exists."""
        return self._path(stage, key).is_dir() and self.damage(stage, key) is None

    def open(self, stage: str, key: str | None = None) -> zarr.Group:
        """Open a complete output read-only (``key=None``: the stage's latest).

        Raises StageOutputDamaged (naming the array and chunk) when files of it are missing.
        """
        if key is None:  # the latest run's output, even damaged (then say so)
            recorded = (r.keys[stage] for r in self.runs() if stage in r.keys)
            key = next(recorded, None) or self.latest(stage)
            if key is None:
                raise StageOutputMissing(f"stage '{stage}' has no output in {self.root}")
        problem = self.damage(stage, key)
        if problem is not None:
            raise StageOutputDamaged(
                f"{stage}/{key[:12]} in {self.root} is damaged: {problem}; "
                "`physanim run` moves it aside and recomputes it"
            )
        if not self._path(stage, key).is_dir():
            raise StageOutputMissing(
                f"no complete output of stage '{stage}' with key {key[:12]} in {self.root}"
            )
        return zarr.open_group(self._path(stage, key), mode="r")

    def provenance(self, stage: str, key: str | None = None) -> dict[str, Any]:
        """Provenance attributes of a complete output (``key=None``: the latest)."""
        return dict(self.open(stage, key).attrs)

    def all_keys(self, stage: str) -> list[str]:
        """Keys of every group at ``<stage>/<key>``, intact or damaged."""
        d = self.root / stage
        return sorted(p.name for p in d.iterdir() if p.is_dir()) if d.is_dir() else []

    def keys(self, stage: str) -> list[str]:
        """Keys of all complete, intact outputs of ``stage``, oldest first."""
        found = [k for k in self.all_keys(stage) if self.has(stage, k)]
        return sorted(found, key=lambda k: (self._path(stage, k) / "zarr.json").stat().st_mtime)

    def stages(self) -> list[str]:
        """Names of stages that have a group in the store."""
        if not self.root.is_dir():
            return []
        return sorted(
            p.name for p in self.root.iterdir() if p.is_dir() and (p / "zarr.json").exists()
        )

    # -- writing ---------------------------------------------------------------------------
    def _tmp_name(self, stage: str, key: str, kind: str = "") -> str:
        head = f"{kind}-{stage}-{key}" if kind else f"{stage}-{key[:16]}"
        return f"{head}-{self._host}-{os.getpid()}-{uuid.uuid4().hex[:8]}"

    @contextlib.contextmanager
    def writing(
        self, stage: str, key: str, provenance: dict[str, Any], *, replace: bool = False
    ) -> Iterator[zarr.Group]:
        """Write one output atomically: yields a fresh group; commits it on normal exit.

        On an exception the temporary copy is removed and the exception propagates.  If another
        writer committed the same key meanwhile, this copy is discarded (same content key).
        ``replace`` (``--force``): an existing output is replaced, only once this one is
        complete.  A damaged group in the way is moved to the quarantine.  ``provenance``'s
        ``varying_inputs`` (stage -> {key, digest}, :meth:`content_digest`) make the output
        stale once one of those outputs is replaced by different content.
        """
        ensure_group(self.root / stage)
        tmp = self.root / TMP / self._tmp_name(stage, key)
        t0 = time.time()
        try:
            group = zarr.open_group(tmp, mode="w")
            group.attrs.update(
                {
                    **provenance,
                    "stage": stage,
                    "key": key,
                    "physanim_version": physanim.__version__,
                    "host": self._host,
                    "started": dt.datetime.fromtimestamp(t0, dt.UTC).isoformat(),
                    "complete": False,
                }
            )
            yield group
            t1 = time.time()
            group.attrs.update(  # written complete, then sealed: the last before the rename
                {
                    "finished": dt.datetime.fromtimestamp(t1, dt.UTC).isoformat(),
                    "duration_s": round(t1 - t0, 6),
                    "manifest": build_manifest(tmp),
                    "complete": True,
                }
            )
            seal_metadata(tmp / "zarr.json")
            self._commit(tmp, stage, key, replace)
        except OSError as exc:
            discard(tmp)
            if exc.filename is None and exc.errno is not None:  # name what failed to be written
                raise OSError(exc.errno, exc.strerror, str(tmp)) from exc
            raise
        except BaseException as exc:
            discard(tmp)
            cause = exc.__cause__  # a stage's failure: its OSError from Zarr names no file
            if isinstance(cause, OSError) and cause.errno is not None and cause.filename is None:
                cause.filename = str(tmp)
            raise

    def _commit(self, tmp: Path, stage: str, key: str, replace: bool) -> None:
        final = self._path(stage, key)
        aside = None
        if final.is_dir():
            problem = self.damage(stage, key)
            if problem is not None:
                moved = self.quarantine(stage, key, problem)
                log.warning("moved damaged %s/%s to %s: %s", stage, key[:12], moved, problem)
            elif replace:
                aside = self.root / TMP / self._tmp_name(stage, key, "replaced")
                with contextlib.suppress(FileNotFoundError):  # another writer moved it first
                    os.rename(final, aside)
        try:
            os.rename(tmp, final)
        except OSError:
            if aside is not None and not final.exists():  # (EIO...): the old output back
                with contextlib.suppress(OSError):  # else the next run puts it back
                    os.rename(aside, final)
                raise
            if not self.has(stage, key):
                raise
            shutil.rmtree(tmp, ignore_errors=True)  # another writer won the race
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)

    def remove(self, stage: str, key: str) -> None:
        """Delete one output (renamed into .tmp first, so it vanishes atomically for readers)."""
        trash = self.root / TMP / self._tmp_name(stage, key, "trash")
        os.rename(self._path(stage, key), trash)
        shutil.rmtree(trash, ignore_errors=True)
