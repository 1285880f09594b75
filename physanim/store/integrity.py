"""Integrity of the store: output manifests, damage and staleness, the quarantine
(``.quarantine/``), abandoned temporaries (``.tmp/``) and atomic small-file writes.

The layout and the guarantees these checks uphold are described in ``stage_store``.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import hashlib
import json
import os
import shutil
import threading
import time
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from physanim.processes import process_alive

TMP = ".tmp"
QUARANTINE = ".quarantine"
#: Attribute of an output's own ``zarr.json``: SHA-256 of the rest of that document (its
#: attributes, the manifest among them, are in no manifest; a flipped bit there is found)
SEAL = "metadata_sha256"
#: Age after which a temporary output of another host is considered abandoned, seconds.
STALE_FOREIGN_S = 24 * 3600


def write_atomic(path: Path, text: str) -> None:
    """Write a small text file by renaming a complete temporary copy into place."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.errno is not None and exc.filename is None:
            exc.filename = str(path)  # (a failed write names no file)
        raise


def group_metadata_ok(meta: Path) -> bool:
    """Whether ``meta`` is the readable ``zarr.json`` of a group."""
    try:
        document = json.loads(meta.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(document, dict) and document.get("node_type") == "group"


def ensure_group(path: Path) -> None:
    """Make ``path`` an (empty) Zarr v3 group if it is not one (or its metadata is unreadable:
    the store's and the stages' groups hold nothing else); safe when processes race.

    The metadata is written to a temporary file and renamed into place, so a concurrent
    reader never sees a half-written zarr.json (Zarr's own writer gives no such guarantee).
    """
    meta = path / "zarr.json"
    if group_metadata_ok(meta):
        return
    path.mkdir(parents=True, exist_ok=True)
    write_atomic(meta, json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {}}))


def _zarr_writes_settled(timeout: float = 60.0) -> None:
    """Wait until the writes in flight on Zarr's I/O loop have ended (at most ``timeout`` s).

    When one chunk write of an array fails (ENOSPC, EIO), Zarr raises at once while the other
    chunk writes of the same assignment go on in its I/O thread; removed before they end, a
    temporary output is recreated by them (their ``mkdir(parents=True)``) and left behind.
    """
    from zarr.core import sync as zarr_sync

    loop, io_thread = zarr_sync.loop[0], zarr_sync.iothread[0]
    if loop is None or loop.is_closed() or threading.current_thread() is io_thread:
        return

    async def the_others_done() -> None:
        me = asyncio.current_task()
        pending = [t for t in asyncio.all_tasks() if t is not me]
        if pending:
            await asyncio.wait(pending, timeout=timeout)

    with contextlib.suppress(Exception):  # a stopped loop has nothing in flight
        asyncio.run_coroutine_threadsafe(the_others_done(), loop).result(timeout + 5)


def discard(path: Path) -> None:
    """Remove a temporary output that failed to be written, once nothing writes to it."""
    _zarr_writes_settled()
    for attempt in range(10):
        shutil.rmtree(path, ignore_errors=True)
        if not path.exists():
            return
        time.sleep(0.01 * 2**attempt)  # a straggling write recreated part of it


def metadata_digest(document: Mapping[str, Any]) -> str:
    """SHA-256 of a group's ``zarr.json`` document without its own ``SEAL`` attribute."""
    attrs = {k: v for k, v in (document.get("attributes") or {}).items() if k != SEAL}
    rest = {**document, "attributes": attrs}
    return hashlib.sha256(json.dumps(rest, sort_keys=True).encode()).hexdigest()


def seal_metadata(meta: Path) -> None:
    """Add ``SEAL`` to the attributes of the group metadata ``meta`` (rewritten atomically)."""
    document = json.loads(meta.read_text())
    document.setdefault("attributes", {})[SEAL] = metadata_digest(document)
    write_atomic(meta, json.dumps(document, indent=2))


def _sha256(path: Path) -> str:
    with path.open("rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def build_manifest(group_dir: Path) -> dict[str, list[Any]]:
    """Relative path -> [size in bytes, SHA-256] of every file of an output group except its
    own ``zarr.json`` (written last, with this manifest in it)."""
    out = {}
    for p in sorted(group_dir.rglob("*")):
        rel = p.relative_to(group_dir).as_posix()
        if p.is_file() and rel != "zarr.json":
            out[rel] = [p.stat().st_size, _sha256(p)]
    return out


def _part(rel: str, manifest: Mapping[str, Any]) -> str:
    """``array 'a/b' chunk c/1/0/0``, ``metadata of array 'a'`` or ``file files/x.png``."""
    parts = rel.split("/")
    for n in range(len(parts) - 1, 0, -1):
        node = "/".join(parts[:n])
        if f"{node}/zarr.json" in manifest:
            rest = "/".join(parts[n:])
            return f"array '{node}' chunk {rest}" if rest != "zarr.json" else f"metadata {rel}"
    if parts[-1] == "zarr.json":
        return f"metadata {rel}"
    return f"file {rel}"


def _owner(name: str) -> tuple[str, int] | None:
    """(host, pid) of a ``.tmp`` entry named ``...-<host>-<pid>-<random>``, else None."""
    parts = name.split("-")
    skip = 3 if parts[0] in ("trash", "replaced") else 2
    try:
        return "-".join(parts[skip:-2]), int(parts[-2])
    except (ValueError, IndexError):
        return None


class StoreIntegrity:
    """The integrity checks and housekeeping of ``StageStore`` (mixed into it)."""

    root: Path
    _host: str

    if TYPE_CHECKING:

        def _path(self, stage: str, key: str) -> Path: ...

    def damage(self, stage: str, key: str, *, checksums: bool = False) -> str | None:
        """What is wrong with the group at ``<stage>/<key>``; None when it is absent or intact.

        Checks that the metadata reads and matches its own checksum (``SEAL``), that the output
        was committed complete and that every file of its manifest is present with its size
        (and, with ``checksums``, its SHA-256), then that no output it was computed from has
        been replaced by different content since.
        Outputs written before manifests existed are taken as they are.
        """
        path = self._path(stage, key)
        if not path.is_dir():
            return None
        meta = path / "zarr.json"
        try:
            document = json.loads(meta.read_text())
            attrs = document.get("attributes", {})
            if not attrs.get("complete"):
                return (
                    "incomplete (complete=false): left by an interrupted or failed writer "
                    f"(metadata {meta})"
                )
            sealed = attrs.get(SEAL)  # (absent: an output of the earlier format)
            if sealed is not None and sealed != metadata_digest(document):
                return f"metadata {meta} does not match its checksum"
        except FileNotFoundError:
            return f"metadata {meta} is missing"
        except (ValueError, OSError, AttributeError, TypeError) as exc:
            return f"metadata {meta} is unreadable ({exc})"
        manifest = attrs.get("manifest")
        if manifest is None:
            return None
        problem = self._file_damage(path, meta, manifest, checksums)
        return problem if problem is not None else self._staleness(attrs)

    def _file_damage(self, path: Path, meta: Path, manifest: Any, checksums: bool) -> str | None:
        """The first file of ``manifest`` missing, resized or (``checksums``) altered."""
        try:
            files = [(rel, int(size), str(digest)) for rel, (size, digest) in manifest.items()]
        except (AttributeError, TypeError, ValueError):
            return f"metadata {meta}: the manifest is unreadable"
        for rel, size, digest in files:
            f = path / rel
            try:
                got = f.stat().st_size
            except FileNotFoundError:
                return f"{_part(rel, manifest)} is missing"
            if got != size:
                return f"{_part(rel, manifest)} has {got} bytes, expected {size}"
            if checksums and _sha256(f) != digest:
                return f"{_part(rel, manifest)} does not match its checksum"
        return None

    def _staleness(self, attrs: Mapping[str, Any]) -> str | None:
        """Why an output no longer follows from its inputs: an upstream output it was computed
        from has since been replaced by different content (``--force`` of a stage whose result
        varies from run to run, such as fTetWild's mesh); None when every input is unchanged."""
        for stage, made_from in (attrs.get("varying_inputs") or {}).items():
            key = made_from.get("key") or ""
            now = self.content_digest(stage, key) if key else None
            if now is not None and now != made_from.get("digest"):
                return (
                    f"stale: computed from an earlier output of {stage} ({key[:12]}), which "
                    "was since recomputed with different content (--force)"
                )
        return None

    def varying_inputs(self, stage: str, key: str) -> dict[str, dict[str, str | None]]:
        """The ``varying_inputs`` an output recorded: stage -> {key, digest} of the outputs
        of ``varies`` stages it was computed from ({} for none or an unreadable output)."""
        return dict((self._attributes(stage, key) or {}).get("varying_inputs") or {})

    def content_digest(self, stage: str, key: str) -> str | None:
        """SHA-256 of an output's manifest (every file's size and checksum): the same for the
        same content; None when the output or its manifest is absent or unreadable."""
        manifest = (self._attributes(stage, key) or {}).get("manifest")
        if manifest is None:
            return None
        return hashlib.sha256(json.dumps(manifest, sort_keys=True).encode()).hexdigest()

    def _attributes(self, stage: str, key: str) -> dict[str, Any] | None:
        """The attributes of ``<stage>/<key>``'s group; None when absent or unreadable."""
        try:
            attrs = json.loads((self._path(stage, key) / "zarr.json").read_text())["attributes"]
        except (OSError, ValueError, KeyError, TypeError):
            return None
        return attrs if isinstance(attrs, dict) else None

    def damaged_groups(self) -> list[Path]:
        """The unreadable ``zarr.json`` of the store's group and of its stages' groups."""
        metas = [self.root / "zarr.json"] if self.root.is_dir() else []
        metas += sorted(self.root.glob("[!.]*/zarr.json")) if self.root.is_dir() else []
        return [m for m in metas if m.exists() and not group_metadata_ok(m)]

    def repair_groups(self) -> list[Path]:
        """Rewrite the unreadable metadata of the store's and its stages' groups (empty groups:
        nothing is lost); returns what was rewritten."""
        damaged = self.damaged_groups()
        for meta in damaged:
            ensure_group(meta.parent)
        return damaged

    # -- quarantine and temporaries --------------------------------------------------------
    def quarantine(self, stage: str, key: str, reason: str) -> Path:
        """Move the group at ``<stage>/<key>`` to ``.quarantine/`` (reason in a .txt beside
        it); returns its new path."""
        stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%S")
        dest = self.root / QUARANTINE / f"{stage}-{key[:16]}-{stamp}-{uuid.uuid4().hex[:6]}"
        dest.parent.mkdir(exist_ok=True)
        os.rename(self._path(stage, key), dest)
        dest.with_suffix(".txt").write_text(f"{stage}/{key}\n{reason}\n")
        return dest

    def quarantined(self) -> list[Path]:
        """Everything in the quarantine (damaged groups and their reason files)."""
        q = self.root / QUARANTINE
        return sorted(q.iterdir()) if q.is_dir() else []

    def stale_temporaries(self) -> list[Path]:
        """Temporary outputs whose writer is gone (dead or zombie local pid, or old foreign
        host)."""
        stale = []
        tmp = self.root / TMP
        for p in tmp.iterdir() if tmp.is_dir() else []:
            owner = _owner(p.name)
            if p.name.startswith("trash-") or owner is None:
                stale.append(p)
            elif owner[0] == self._host:
                if not process_alive(owner[1], started_before=p.stat().st_mtime):
                    stale.append(p)
            elif time.time() - p.stat().st_mtime > STALE_FOREIGN_S:
                stale.append(p)
        return stale

    def remove_stale_temporaries(self) -> list[Path]:
        """Delete abandoned temporary outputs; returns what was removed.

        An old output that a killed ``--force`` run had moved aside just before renaming its
        new one into place is put back when its final path is still empty.
        """
        removed = []
        for p in self.stale_temporaries():
            parts = p.name.split("-")
            if parts[0] == "replaced" and not self._path(parts[1], parts[2]).exists():
                os.rename(p, self._path(parts[1], parts[2]))
                continue
            shutil.rmtree(p, ignore_errors=True)
            if not p.exists():  # (a read-only store keeps it)
                removed.append(p)
        return removed
