"""Content keys of stage outputs: sha256 over the stage's identity, params and upstream keys."""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any


def canonical_json(value: Any) -> str:
    """Serialise ``value`` to JSON with sorted keys and no whitespace, so equal values hash equally.

    Floats are written by ``repr`` (shortest round-trip form), so ``0.1`` and ``1e-1`` agree;
    NaN and infinities are refused because they have no canonical JSON form (the ValueError
    starts with the dotted path of the value, e.g. ``params.dt: ...``).
    """

    def check(v: Any, path: str) -> None:
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{path}: {v!r} is not a finite number; use a finite value")
        if isinstance(v, Mapping):
            for k, item in v.items():
                check(item, f"{path}.{k}" if path else str(k))
        elif isinstance(v, list | tuple):
            for i, item in enumerate(v):
                check(item, f"{path}[{i}]")

    check(value, "")
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True)


def stage_key(
    stage: str, version: str, params: Mapping[str, Any], upstream: Mapping[str, str]
) -> str:
    """Key of a stage output: sha256 hex of (stage name, code version, params, upstream keys).

    ``params`` is the validated, JSON-able parameter dict (plus any input fingerprint);
    ``upstream`` maps each upstream stage name to its output key.
    """
    canonical_json(dict(params))  # errors name the parameter, e.g. "params.dt: ..."
    payload = canonical_json(
        {"stage": stage, "version": version, "params": dict(params), "upstream": dict(upstream)}
    )
    return hashlib.sha256(payload.encode("ascii")).hexdigest()


def files_fingerprint(files: Iterable[Path], root: Path) -> list[list[object]]:
    """[path relative to ``root``, size bytes, mtime ns] of each file: what an input-file
    fingerprint needs (size + mtime, not a content hash, keeps warm runs fast on large
    recordings; an edited or regenerated file changes them)."""
    return [
        [p.relative_to(root).as_posix(), p.stat().st_size, p.stat().st_mtime_ns]
        for p in sorted(files)
    ]
