"""Runs of the store: the run manifests (``.runs/``), the ``LATEST`` pointer, and which outputs
a set of runs still uses (its upstream closure).

The layout these belong to is described in ``stage_store``.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import logging
import os
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from physanim.store.integrity import write_atomic

RUNS = ".runs"
LATEST = "LATEST"

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class RunRecord:
    """One run manifest: its file name, the stage keys the run used and facts about the run
    (``pipeline``, ``complete``: every stage of the pipeline has an output, ``finished``...)."""

    name: str
    keys: Mapping[str, str]
    info: Mapping[str, Any]


class StoreRuns:
    """The run records of ``StageStore`` (mixed into it; reads outputs through its methods)."""

    root: Path

    if TYPE_CHECKING:

        def has(self, stage: str, key: str) -> bool: ...
        def keys(self, stage: str) -> list[str]: ...
        def stages(self) -> list[str]: ...
        def provenance(self, stage: str, key: str | None = None) -> dict[str, Any]: ...

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
            write_atomic(self.root / RUNS / name, json.dumps(record, indent=1, default=str))
        if latest and self.latest_run_name() != name:
            write_atomic(self.root / LATEST, name + "\n")
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
