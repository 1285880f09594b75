"""Content-addressed Zarr v3 store of stage outputs.

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
size and SHA-256 of every file of the group (array metadata, chunks, plain files).  Every read
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
import dataclasses
import datetime as dt
import functools
import hashlib
import json
import logging
import os
import shutil
import socket
import time
import typing
import uuid
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import zarr

import physanim
from physanim.processes import process_alive

T = TypeVar("T")

TMP = ".tmp"
QUARANTINE = ".quarantine"
RUNS = ".runs"
LATEST = "LATEST"
#: Target size of one chunk, bytes; arrays are chunked along their first (frame) axis only.
CHUNK_BYTES = 4 * 2**20
#: Age after which a temporary output of another host is considered abandoned, seconds.
STALE_FOREIGN_S = 24 * 3600

log = logging.getLogger(__name__)


class StageOutputMissing(LookupError):
    """No complete output exists for the requested stage and key."""


class StageOutputDamaged(StageOutputMissing):
    """An output exists at its final path but is damaged (missing or altered files, unreadable
    or incomplete metadata); the message names stage, key, array and chunk."""


@dataclasses.dataclass(frozen=True)
class RunRecord:
    """One run manifest: its file name, the stage keys the run used and facts about the run
    (``pipeline``, ``complete``: every stage of the pipeline has an output, ``finished``...)."""

    name: str
    keys: Mapping[str, str]
    info: Mapping[str, Any]


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


def stored_name(f: dataclasses.Field[Any]) -> str:
    """The name a dataclass field is stored under: ``metadata={"stored": ...}`` or its own."""
    return str(f.metadata.get("stored", f.name))


def write_dataclass(group: zarr.Group, record: object, prefix: str = "") -> None:
    """Write each numpy-array field of dataclass ``record`` as ``<prefix>/<field>``.

    Scalar fields (numbers, strings, bools, lists of them) go to the group's attributes;
    a nested dataclass goes to the subgroup ``<prefix>/<field>``, a non-empty dict of
    dataclasses to one subgroup per key.  A field's ``metadata={"stored": name}`` stores it
    under another name (``""``: a dict of dataclasses directly in ``<prefix>``).
    """
    target = group.require_group(prefix) if prefix else group
    for f in dataclasses.fields(record):  # type: ignore[arg-type]
        value, name = getattr(record, f.name), stored_name(f)
        if isinstance(value, np.ndarray):
            write_array(target, name, value)
        elif _is_record(value):
            write_dataclass(target, value, name)
        elif isinstance(value, dict) and value and all(map(_is_record, value.values())):
            for k, v in value.items():
                write_dataclass(target, v, f"{name}/{k}" if name else k)
        elif isinstance(value, str | int | float | bool | list | tuple | dict) or value is None:
            target.attrs[name] = value
        else:
            raise TypeError(f"cannot store field {f.name!r} of type {type(value).__name__}")


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints`` of a dataclass, once per class."""
    return typing.get_type_hints(cls)


def _is_record(value: object) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _dataclass_of(cls: type, name: str) -> type:
    """The dataclass type of field ``name`` of ``cls`` (``X`` or ``X | None``)."""
    hint = _hints(cls)[name]
    for t in (hint, *typing.get_args(hint)):
        if isinstance(t, type) and dataclasses.is_dataclass(t):
            return t
    raise TypeError(f"{cls.__name__}.{name}: stored as a group, but {hint} is not a dataclass")


def read_dataclass(cls: type[T], group: zarr.Group) -> T:
    """Rebuild a dataclass written by ``write_dataclass`` from its group.

    Nested dataclass fields are read from their subgroups; a field with
    ``metadata={"lazy": True}`` is returned as the read-only Zarr array (sliced by the
    reader: large per-frame arrays), the others as numpy arrays or attribute values.  A field
    absent from the group takes its default; without one, KeyError names the field and group.
    """
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if not f.init:
            continue
        name = stored_name(f)
        hint = _hints(cls)[f.name] if name == "" or name in group else None
        if typing.get_origin(hint) is dict:  # a dict of dataclasses, one subgroup per key
            record = typing.get_args(hint)[1]
            where = group[name] if name else group
            kwargs[f.name] = {k: read_dataclass(record, g) for k, g in sorted(where.groups())}
        elif name in group:
            node = group[name]
            if isinstance(node, zarr.Group):  # a nested dataclass
                kwargs[f.name] = read_dataclass(_dataclass_of(cls, f.name), node)
            else:
                kwargs[f.name] = node if f.metadata.get("lazy") else node[...]
        elif name in group.attrs:
            kwargs[f.name] = group.attrs[name]
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise KeyError(f"{group.store}/{group.path}: no '{name}' ({cls.__name__}.{f.name})")
    return cls(**kwargs)


def _write_atomic(path: Path, text: str) -> None:
    """Write a small text file by renaming a complete temporary copy into place."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _ensure_group(path: Path) -> None:
    """Make ``path`` an (empty) Zarr v3 group if it is not one; safe when processes race.

    The metadata is written to a temporary file and renamed into place, so a concurrent
    reader never sees a half-written zarr.json (Zarr's own writer gives no such guarantee).
    """
    meta = path / "zarr.json"
    if meta.exists():
        return
    path.mkdir(parents=True, exist_ok=True)
    _write_atomic(meta, json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {}}))


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


class StageStore:
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
            _ensure_group(self.root)
            (self.root / TMP).mkdir(exist_ok=True)

    # -- reading ---------------------------------------------------------------------------
    def _path(self, stage: str, key: str) -> Path:
        return self.root / stage / key

    def files(self, stage: str, key: str) -> Path:
        """Directory of the plain files (PNG, MP4) of an output; absent if it wrote none."""
        return self._path(stage, key).resolve() / "files"

    def damage(self, stage: str, key: str, *, checksums: bool = False) -> str | None:
        """What is wrong with the group at ``<stage>/<key>``; None when it is absent or intact.

        Checks that the metadata reads, that the output was committed complete and that every
        file of its manifest is present with its size (and, with ``checksums``, its SHA-256),
        then that no output it was computed from has been replaced by different content since.
        Outputs written before manifests existed are taken as they are.
        """
        path = self._path(stage, key)
        if not path.is_dir():
            return None
        meta = path / "zarr.json"
        try:
            attrs = json.loads(meta.read_text()).get("attributes", {})
        except FileNotFoundError:
            return f"metadata {meta} is missing"
        except (ValueError, OSError, AttributeError) as exc:
            return f"metadata {meta} is unreadable ({exc})"
        if not attrs.get("complete"):
            return "incomplete (complete=false): left by an interrupted or failed writer"
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

    # -- runs and LATEST -------------------------------------------------------------------
    def runs(self) -> list[RunRecord]:
        """Every readable run manifest, the latest run first, then newest first."""
        d = self.root / RUNS
        records = []
        for p in sorted(d.glob("*.json"), reverse=True) if d.is_dir() else []:
            try:
                data = json.loads(p.read_text())
                records.append(RunRecord(p.name, dict(data["keys"]), data.get("info", {})))
            except (OSError, ValueError, KeyError, TypeError):
                log.warning("skipping unreadable run manifest %s", p)
        latest = self.latest_run_name()
        return sorted(records, key=lambda r: r.name != latest)  # stable: keeps newest first

    def latest_run_name(self) -> str | None:
        """File name of the latest run's manifest (the ``LATEST`` pointer), or None."""
        try:
            return (self.root / LATEST).read_text().strip() or None
        except OSError:
            return None

    def latest(self, stage: str) -> str | None:
        """Key of the stage's default output: its key in the latest run that has an intact
        output of it (the latest run first); None if no run has one."""
        for run in self.runs():
            key = run.keys.get(stage)
            if key is not None and self.has(stage, key):
                return key
        legacy = self.root / stage / LATEST  # per-stage pointer of stores from before runs
        key = legacy.read_text().strip() if legacy.is_file() else None
        return key if key and self.has(stage, key) else None

    def record_run(
        self, keys: Mapping[str, str], info: Mapping[str, Any], *, latest: bool = True
    ) -> str:
        """Record a run's stage keys in a run manifest (atomically); with ``latest``, point
        ``LATEST`` at it.  A manifest with the same keys is reused, so a run that changed
        nothing writes nothing.  Returns the manifest's file name."""
        keys = dict(keys)
        same = [r for r in self.runs() if r.keys == keys]
        if same:
            name = same[0].name
        else:
            now = dt.datetime.now(dt.UTC)
            name = f"{now:%Y%m%dT%H%M%S%f}-{os.getpid()}-{uuid.uuid4().hex[:6]}.json"
            record = {"keys": keys, "info": {**info, "finished": now.isoformat()}}
            (self.root / RUNS).mkdir(exist_ok=True)
            _write_atomic(self.root / RUNS / name, json.dumps(record, indent=1, default=str))
        if latest and self.latest_run_name() != name:
            _write_atomic(self.root / LATEST, name + "\n")
        return name

    def adopt_unrecorded(self, pipeline: str, stages: Iterable[str]) -> None:
        """Give a store written before run manifests existed one run (not the latest) per
        output that no other output was computed from, with the outputs it was computed from;
        ``complete`` when those cover ``stages``.  Does nothing once the store has runs."""
        if (self.root / RUNS).exists() or not (self.root / "zarr.json").exists():
            return
        (self.root / RUNS).mkdir()
        outputs = [(s, k) for s in self.stages() for k in self.keys(s)]
        used = {u for s, k in outputs for u in self.provenance(s, k).get("upstream", {}).items()}
        wanted = set(stages)
        for leaf in (o for o in outputs if o not in used):
            keys = dict(sorted(self.closure([leaf])))
            info = {"pipeline": pipeline, "complete": wanted <= set(keys), "adopted": True}
            self.record_run(keys, info, latest=False)

    def remove_run(self, name: str) -> None:
        """Delete one run manifest (never the latest run's)."""
        if name != self.latest_run_name():
            (self.root / RUNS / name).unlink(missing_ok=True)

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
        _ensure_group(self.root / stage)
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
            group.attrs.update(  # the last metadata write before the rename
                {
                    "finished": dt.datetime.fromtimestamp(t1, dt.UTC).isoformat(),
                    "duration_s": round(t1 - t0, 6),
                    "manifest": build_manifest(tmp),
                    "complete": True,
                }
            )
            self._commit(tmp, stage, key, replace)
        except OSError as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            if exc.filename is None and exc.errno is not None:  # name what failed to be written
                raise OSError(exc.errno, exc.strerror, str(tmp)) from exc
            raise
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
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
            if not self.has(stage, key):
                raise
            shutil.rmtree(tmp, ignore_errors=True)  # another writer won the race
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)

    def quarantine(self, stage: str, key: str, reason: str) -> Path:
        """Move the group at ``<stage>/<key>`` to ``.quarantine/`` (reason in a .txt beside
        it); returns its new path."""
        stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%S")
        dest = self.root / QUARANTINE / f"{stage}-{key[:16]}-{stamp}-{uuid.uuid4().hex[:6]}"
        dest.parent.mkdir(exist_ok=True)
        os.rename(self._path(stage, key), dest)
        dest.with_suffix(".txt").write_text(f"{stage}/{key}\n{reason}\n")
        return dest

    # -- housekeeping ----------------------------------------------------------------------
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
            removed.append(p)
        return removed

    def quarantined(self) -> list[Path]:
        """Everything in the quarantine (damaged groups and their reason files)."""
        q = self.root / QUARANTINE
        return sorted(q.iterdir()) if q.is_dir() else []

    def closure(self, outputs: Iterable[tuple[str, str]]) -> set[tuple[str, str]]:
        """``outputs`` and, through their provenance, every output they were computed from."""
        seen: set[tuple[str, str]] = set()
        todo = list(outputs)
        while todo:
            stage, key = todo.pop()
            if (stage, key) in seen:
                continue
            seen.add((stage, key))
            if self.has(stage, key):
                todo += self.provenance(stage, key).get("upstream", {}).items()
        return seen

    def unreachable(self, keep: Iterable[tuple[str, str]]) -> list[tuple[str, str]]:
        """Intact outputs outside the upstream closure of ``keep``."""
        kept = self.closure(keep)
        return [(s, k) for s in self.stages() for k in self.keys(s) if (s, k) not in kept]

    def remove(self, stage: str, key: str) -> None:
        """Delete one output (renamed into .tmp first, so it vanishes atomically for readers)."""
        trash = self.root / TMP / self._tmp_name(stage, key, "trash")
        os.rename(self._path(stage, key), trash)
        shutil.rmtree(trash, ignore_errors=True)
