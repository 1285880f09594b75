"""Generate ``docs/PERFORMANCE.md`` from ``benchmarks/results/*.json`` (and nothing else).

One section per benchmark (anchor ``#bench_x``): what it measures, its command, the latest
run's tables with their date, commit and host, then a history table (date, commit, headline
figures) of the earlier runs and those runs in full. The output depends only on the JSON
files: no clock, files read in sorted order, runs ordered by their dates.

Run: .venv/bin/python benchmarks/perf_doc.py [--check] [--results DIR] [--out FILE]
``--check`` writes nothing: it exits with 1 and prints a diff when the file is out of date.
"""

from __future__ import annotations

import argparse
import difflib
import json
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
OUT = ROOT / "docs" / "PERFORMANCE.md"
GENERATOR = "benchmarks/perf_doc.py"


def load_results(results: Path = RESULTS) -> list[dict[str, Any]]:
    """Every results document in ``results``, sorted by file name, each checked for the
    fields the page needs (ValueError naming the file otherwise)."""
    docs = []
    for path in sorted(results.glob("*.json")):
        doc = json.loads(path.read_text())
        where = path.name
        if not isinstance(doc, dict) or not isinstance(doc.get("runs"), list) or not doc["runs"]:
            raise ValueError(f"{where}: expected an object with a non-empty list 'runs'")
        doc.setdefault("benchmark", path.stem)
        for i, run in enumerate(doc["runs"]):
            if not isinstance(run.get("date"), str) or not run.get("tables"):
                raise ValueError(f"{where}: run {i} lacks 'date' or 'tables'")
            for t in run["tables"]:
                n = len(t.get("columns", []))
                if not n or any(len(r) != n for r in t.get("rows", [])):
                    raise ValueError(f"{where}: run {i}, table {t.get('name')!r}: rows and "
                                     "columns disagree")  # fmt: skip
        doc["runs"] = sorted(doc["runs"], key=lambda r: r["date"])  # stable: ties keep order
        docs.append(doc)
    return docs


def fmt_number(x: float | int) -> str:
    """A number as written in the tables: integers as they are, floats shortest, very large
    or small ones in exponent form."""
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, int):
        return str(x)
    if x == 0:
        return "0"
    if abs(x) >= 1e7 or abs(x) < 1e-3:
        return f"{x:.3g}"
    return repr(float(f"{x:.4g}"))


def fmt_cell(cell: Any) -> str:
    """A cell as Markdown text: ranges as ``min-max``, lists comma-separated, null empty."""
    if cell is None:
        return ""
    if isinstance(cell, bool | int | float):
        return fmt_number(cell)
    if isinstance(cell, str):
        return cell.replace("|", "\\|").replace("\n", " ")
    if isinstance(cell, Mapping) and set(cell) == {"min", "max"}:
        lo, hi = fmt_cell(cell["min"]), fmt_cell(cell["max"])
        return lo if lo == hi else f"{lo} to {hi}" if lo.startswith("-") else f"{lo}-{hi}"
    if isinstance(cell, Sequence):
        return ", ".join(fmt_cell(c) for c in cell)
    if isinstance(cell, Mapping):
        return "; ".join(f"{k} {fmt_cell(v)}" for k, v in cell.items())
    raise TypeError(f"cannot write a {type(cell).__name__} cell")


def md_table(columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> list[str]:
    """Markdown table lines."""
    lines = ["| " + " | ".join(fmt_cell(c) for c in columns) + " |"]
    lines.append("|" + "---|" * len(columns))
    lines += ["| " + " | ".join(fmt_cell(c) for c in row) + " |" for row in rows]
    return lines


def short_date(date: str) -> str:
    """``2026-12-02T10:54:25Z`` -> ``2026-12-02 10:54``."""
    return date[:16].replace("T", " ")


def host_line(run: Mapping[str, Any]) -> str:
    """One line: when, which commit, where, with which arguments."""
    host = run.get("host") or {}
    parts = [f"{short_date(run['date'])} UTC"]
    commit = run.get("commit")
    if commit:
        parts.append(
            f"commit {commit}" + (" (with uncommitted changes)" if run.get("dirty") else "")
        )
    if host.get("cores"):
        parts.append(f"{host['cores']} cores")
    load = host.get("load_average")
    if load is not None:
        parts.append(f"load average {fmt_cell(load)}")
    for key, name in (("python", "Python"), ("numpy", "numpy")):
        if host.get(key):
            parts.append(f"{name} {host[key]}")
    if run.get("args"):
        parts.append("arguments `" + " ".join(run["args"]) + "`")
    if run.get("source"):
        parts.append(f"source: {run['source']}")
    return "; ".join(parts) + "."


def run_tables(run: Mapping[str, Any]) -> list[str]:
    """A run's notes and tables as Markdown lines."""
    lines = []
    if run.get("notes"):
        lines += [run["notes"], ""]
    for t in run["tables"]:
        lines += [f"**{fmt_cell(t['name'])}**", ""]
        lines += md_table(t["columns"], t["rows"])
        after = []
        if t.get("notes"):
            after.append(t["notes"])
        if t.get("reference"):
            after.append(f"Reference: {t['reference']}")
        lines += ["", *(" ".join(after).split("\n") if after else [])]
        if after:
            lines.append("")
    return lines


def history(runs: Sequence[Mapping[str, Any]]) -> list[str]:
    """The compact table of earlier runs, newest first: date, commit, run, headline figures
    (the union of their names, in order of first use from the newest run)."""
    keys: list[str] = []
    for run in runs:
        keys += [k for k in run.get("headline", {}) if k not in keys]
    rows = [
        [short_date(r["date"]), r.get("commit") or "", r.get("label", "")]
        + [r.get("headline", {}).get(k) for k in keys]
        for r in runs
    ]
    return md_table(["date (UTC)", "commit", "run", *keys], rows)


def section(doc: Mapping[str, Any]) -> list[str]:
    """One benchmark's section."""
    name = doc["benchmark"]
    runs = doc["runs"]
    latest, earlier = runs[-1], runs[-2::-1]
    lines = [f"## {name}", ""]
    if doc.get("about"):
        lines += [doc["about"], ""]
    command = doc.get("command") or f".venv/bin/python benchmarks/{name}.py"
    lines += ["```bash", command, "```", ""]
    title = f"### Latest run: {short_date(latest['date'])}"
    lines += [title + (f", {latest['label']}" if latest.get("label") else ""), ""]
    lines += [host_line(latest), ""]
    lines += run_tables(latest)
    if earlier:
        lines += [f"### History of {name}", "", "Earlier runs, newest first:", ""]
        lines += history(earlier)
        lines += ["", "<details><summary>Earlier runs in full</summary>", ""]
        for run in earlier:
            head = f"{short_date(run['date'])}" + (f", {run['label']}" if run.get("label") else "")
            lines += [f"#### {name}, {head}", "", host_line(run), ""]
            lines += run_tables(run)
        lines += ["</details>", ""]
    return lines


def render(docs: Sequence[Mapping[str, Any]]) -> str:
    """The whole page."""
    lines = [
        "# Performance",
        "",
        f"<!-- Generated by {GENERATOR} from benchmarks/results/*.json; edit those, "
        "not this file. -->",
        "",
        "Every figure here is read from `benchmarks/results/<benchmark>.json`, where each "
        "benchmark script records its runs (`benchmarks/results.py`: date, commit, host, "
        "tables with units in their column names). `make bench` runs the benchmarks and "
        "regenerates this page; `make docs` or `.venv/bin/python benchmarks/perf_doc.py` "
        "regenerates it alone, and `tests/foundation/test_performance_doc.py` checks that it "
        "matches the committed JSON. Runs whose source is `README.md at <commit>` were "
        "transcribed from the README's earlier prose: their date and commit are those of the "
        "commit that first reported them, and a figure stated as a range is stored as its "
        "minimum and maximum.",
        "",
        "| benchmark | latest run | runs recorded |",
        "|---|---|---|",
    ]
    for doc in docs:
        name, runs = doc["benchmark"], doc["runs"]
        lines.append(f"| [{name}](#{name}) | {short_date(runs[-1]['date'])} | {len(runs)} |")
    lines.append("")
    for doc in docs:
        lines += section(doc)
    while lines[-1] == "":
        lines.pop()
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 with a diff when out of date")
    ap.add_argument("--results", type=Path, default=RESULTS, help="folder of the JSON files")
    ap.add_argument("--out", type=Path, default=OUT, help="the page to write or check")
    args = ap.parse_args(argv)
    text = render(load_results(args.results))
    current = args.out.read_text() if args.out.exists() else ""
    if args.check:
        if current == text:
            print(f"{args.out} is up to date")
            return 0
        sys.stdout.writelines(
            difflib.unified_diff(
                current.splitlines(keepends=True),
                text.splitlines(keepends=True),
                f"{args.out} (committed)",
                f"{args.out} (from the JSON)",
            )  # fmt: skip
        )
        print(f"\n{args.out} is out of date: run .venv/bin/python {GENERATOR}")
        return 1
    if current != text:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
        print(f"wrote {args.out}")
    else:
        print(f"{args.out} unchanged")
    return 0


if __name__ == "__main__":
    sys.exit(main())
