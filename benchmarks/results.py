"""Machine-readable benchmark results: every ``benchmarks/bench_*.py`` records its run here.

``record(benchmark, tables)`` appends one dated run entry to
``benchmarks/results/<benchmark>.json``, a JSON document::

    {"benchmark": "bench_fem", "about": "...", "command": "...", "runs": [run, ...]}

with the runs oldest first (the latest last). A run entry holds:

- ``date``: ISO 8601 date and time in UTC (``2026-12-02T17:40:00Z``);
- ``commit``: the git commit's short hash (``null`` outside a git checkout) and ``dirty``:
  whether tracked files differed from it;
- ``source``: where the figures come from (``benchmarks/bench_fem.py`` for a recorded run;
  ``README.md at <commit>`` for the figures transcribed from the README's prose);
- ``host``: ``cores``, ``load_average`` (1, 5 and 15 min, or a ``{"min", "max"}`` range as
  stated), ``python`` and ``numpy`` versions;
- ``args``: the script's command-line arguments;
- ``label`` (optional): a short title of the run; ``headline`` (optional): the few figures the
  history table of ``docs/PERFORMANCE.md`` shows, name -> value;
- ``notes`` (optional) and ``tables``: one or more named tables, each with ``columns``
  (units in the names: ``wall_s``, ``ms_per_step``, ``frames_per_s``), ``rows`` and optional
  ``notes`` and ``reference`` (what the figures are compared against).

A cell is a number, a string, ``null``, a list of numbers (e.g. the single runs behind a
median) or ``{"min": a, "max": b}`` (a range, as a figure was stated). Floats are stored
to 6 significant digits, NaN and infinities as ``null``.

The file is written atomically (a temporary file beside it, then ``os.replace``): a run
that fails to serialise leaves the previous file as it was. ``benchmarks/perf_doc.py``
renders ``docs/PERFORMANCE.md`` from these files.
"""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: Where the JSON files live (one per benchmark)
RESULTS_DIR = Path(__file__).resolve().parent / "results"

#: A table cell: number, text, null, list of numbers or {"min": a, "max": b}
Cell = float | int | str | None | list[float] | dict[str, float]


@dataclass
class Table:
    """One named table of a run. Column names carry their units (``wall_s``, ``ms_per_step``);
    each row has one cell per column."""

    name: str
    columns: Sequence[str]
    rows: Sequence[Sequence[Any]]
    notes: str | None = None
    reference: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The table as stored in the JSON document."""
        for i, row in enumerate(self.rows):
            if len(row) != len(self.columns):
                raise ValueError(
                    f"table {self.name!r}: row {i} has {len(row)} cells for "
                    f"{len(self.columns)} columns"
                )
        out: dict[str, Any] = {"name": self.name, "columns": list(self.columns)}
        out["rows"] = [list(r) for r in self.rows]
        if self.notes:
            out["notes"] = self.notes
        if self.reference:
            out["reference"] = self.reference
        out.update(self.extra)
        return out


def span(values: Sequence[float]) -> dict[str, float]:
    """A range cell ``{"min", "max"}`` of ``values``."""
    return {"min": min(values), "max": max(values)}


def describe(docstring: str | None, benchmark: str) -> dict[str, str]:
    """``about`` (the docstring's first paragraph on one line) and ``command`` (its ``Run:`` or
    ``Usage:`` line, continuation lines joined, run by the project's venv) of a script."""
    text = (docstring or "").strip()
    about = " ".join(text.split("\n\n")[0].split())
    command = f".venv/bin/python benchmarks/{benchmark}.py"
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith(("Run:", "Usage:")):
            parts = [line.split(":", 1)[1].strip()]
            for more in lines[i + 1 :]:
                if not more.startswith(" ") or not more.strip():
                    break
                parts.append(more.strip())
            command = " ".join(parts)
            if command.startswith("python "):
                command = ".venv/bin/" + command
            break
    return {"about": about, "command": command}


def _plain(value: Any) -> Any:
    """``value`` as JSON types: numpy scalars and arrays converted, floats to 6 significant
    digits, NaN/inf as None. Raises TypeError for anything else."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            return None
        return float(f"{value:.6g}")
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist") and type(value).__module__ == "numpy":  # arrays and scalars
        return _plain(value.tolist())
    raise TypeError(f"cannot record a {type(value).__name__} in a benchmark result: {value!r}")


def git_commit(root: Path = ROOT) -> tuple[str | None, bool]:
    """(short hash of HEAD, whether tracked files differ from it); (None, False) without git."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root,
                              capture_output=True, text=True, timeout=10, check=True)  # fmt: skip
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                                cwd=root, capture_output=True, text=True, timeout=30)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None, False
    return head.stdout.strip() or None, bool(status.stdout.strip())


def host_facts() -> dict[str, Any]:
    """Cores, load average (1, 5, 15 min), python and numpy versions, machine."""
    facts: dict[str, Any] = {"cores": os.cpu_count()}
    try:
        facts["load_average"] = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        facts["load_average"] = None
    facts["python"] = platform.python_version()
    try:
        import numpy

        facts["numpy"] = numpy.__version__
    except ImportError:
        facts["numpy"] = None
    facts["machine"] = platform.machine()
    return facts


def load(path: Path) -> dict[str, Any]:
    """A results document (an empty one when the file does not exist)."""
    if not path.exists():
        return {"benchmark": path.stem, "runs": []}
    doc = json.loads(path.read_text())
    if not isinstance(doc, dict) or not isinstance(doc.get("runs"), list):
        raise ValueError(f"{path}: not a benchmark results document (no list 'runs')")
    return doc


def write_atomic(path: Path, doc: Mapping[str, Any]) -> None:
    """Write ``doc`` as JSON to ``path`` through a temporary file and ``os.replace``: on any
    failure the previous file stays as it was and the temporary file is removed."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(doc, f, indent=1, ensure_ascii=False, allow_nan=False)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def record(
    benchmark: str,
    tables: Sequence[Table | Mapping[str, Any]],
    *,
    about: str | None = None,
    command: str | None = None,
    label: str | None = None,
    headline: Mapping[str, Any] | None = None,
    notes: str | None = None,
    host: Mapping[str, Any] | None = None,
    args: Sequence[str] | None = None,
    results_dir: Path | None = None,
    now: datetime | None = None,
) -> Path:
    """Append one run of ``benchmark`` (e.g. ``"bench_fem"``) to its results file and return
    the file's path.

    ``tables``: the run's tables (``Table`` or dicts with ``name``, ``columns``, ``rows``).
    ``about``/``command``: what the benchmark measures and how to run it (kept at the top of the
    document; the latest given wins). ``headline``: the figures for the history table.
    ``host``: facts to add to or override the measured ones (e.g. the load average before and
    after). ``args``: the command-line arguments (default ``sys.argv[1:]``).
    """
    path = (results_dir or RESULTS_DIR) / f"{benchmark}.json"
    commit, dirty = git_commit()
    run: dict[str, Any] = {
        "date": (now or datetime.now(UTC)).astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "commit": commit,
        "dirty": dirty,
        "source": f"benchmarks/{benchmark}.py",
        "args": list(sys.argv[1:] if args is None else args),
        "host": {**host_facts(), **(host or {})},
    }
    if label:
        run["label"] = label
    if headline:
        run["headline"] = dict(headline)
    if notes:
        run["notes"] = notes
    run["tables"] = [t.as_dict() if isinstance(t, Table) else dict(t) for t in tables]
    if not run["tables"]:
        raise ValueError("a run needs at least one table")
    run = _plain(run)
    old = load(path)
    doc = {"benchmark": benchmark}
    for key, given in (("about", about), ("command", command)):
        if given or old.get(key):
            doc[key] = given or old[key]
    doc.update({k: v for k, v in old.items() if k not in ("benchmark", "about", "command")})
    doc["runs"] = [*old["runs"], run]
    write_atomic(path, doc)
    print(f"recorded in {os.path.relpath(path)} (run {len(doc['runs'])})")
    return path
