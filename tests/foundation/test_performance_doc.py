"""docs/PERFORMANCE.md is generated from benchmarks/results/*.json and kept in sync with it;
benchmarks/results.py appends runs without losing earlier ones and writes atomically."""

from __future__ import annotations

import json
import shutil
from datetime import UTC, datetime
from pathlib import Path

import pytest

from benchmarks import perf_doc, results

ROOT = Path(__file__).resolve().parents[2]


def test_committed_page_matches_the_committed_json() -> None:
    expected = perf_doc.render(perf_doc.load_results(perf_doc.RESULTS))
    committed = (ROOT / "docs" / "PERFORMANCE.md").read_text()
    assert committed == expected, (
        "docs/PERFORMANCE.md is out of date: run .venv/bin/python benchmarks/perf_doc.py"
    )
    for doc in perf_doc.load_results(perf_doc.RESULTS):  # a stable anchor per benchmark
        assert f"\n## {doc['benchmark']}\n" in committed


def test_the_page_follows_the_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "results"
    shutil.copytree(perf_doc.RESULTS, data)
    page = tmp_path / "PERFORMANCE.md"
    assert perf_doc.main(["--results", str(data), "--out", str(page)]) == 0
    assert perf_doc.main(["--check", "--results", str(data), "--out", str(page)]) == 0
    assert page.read_text() == (ROOT / "docs" / "PERFORMANCE.md").read_text()

    path = data / "bench_fem.json"
    doc = json.loads(path.read_text())
    latest = doc["runs"][-1]
    latest["tables"][0]["rows"][0][1] = 987.6
    latest["headline"] = {**latest.get("headline", {}), "default_s": 123.4}
    path.write_text(json.dumps(doc))
    capsys.readouterr()
    assert perf_doc.main(["--check", "--results", str(data), "--out", str(page)]) == 1
    diff = capsys.readouterr().out
    assert "+| " in diff and "987.6" in diff
    assert perf_doc.main(["--results", str(data), "--out", str(page)]) == 0
    text = page.read_text()
    assert "987.6" in text


def test_history_lists_earlier_runs_newest_first(tmp_path: Path) -> None:
    table = results.Table("t", ["case", "wall_s"], [["a", 1.5]])
    for day, value in ((1, 11.0), (2, 22.0), (3, 33.0)):
        results.record("bench_x", [table], headline={"wall_s": value}, about="What x measures.",
                       command=".venv/bin/python benchmarks/bench_x.py", args=[],
                       results_dir=tmp_path, now=datetime(2026, 1, day, tzinfo=UTC))  # fmt: skip
    text = perf_doc.render(perf_doc.load_results(tmp_path))
    assert "## bench_x\n\nWhat x measures." in text
    assert "### Latest run: 2026-01-03 00:00" in text
    history = text[text.index("### History of bench_x") :]
    assert history.index("| 22.0 |") < history.index("| 11.0 |")
    assert "| 33.0 |" not in history.split("<details>")[0]


def test_record_appends_and_keeps_earlier_runs(tmp_path: Path) -> None:
    first = results.record(
        "bench_x",
        [results.Table("t", ["case", "wall_s", "runs_s"], [["a", 1.23456789, [1.0, 2.0]]])],
        about="What x measures.",
        args=["--fast"],
        results_dir=tmp_path,
        now=datetime(2026, 1, 1, 12, 0, tzinfo=UTC),
    )
    second = results.record(
        "bench_x",
        [{"name": "t", "columns": ["case", "wall_s"], "rows": [["b", float("nan")]]}],
        headline={"wall_s": results.span([2.0, 3.0])},
        results_dir=tmp_path,
    )
    assert first == second == tmp_path / "bench_x.json"
    doc = json.loads(first.read_text())
    assert doc["about"] == "What x measures."  # kept when a later run gives none
    runs = doc["runs"]
    assert len(runs) == 2
    assert runs[0]["date"] == "2026-01-01T12:00:00Z" and runs[0]["args"] == ["--fast"]
    assert runs[0]["tables"][0]["rows"] == [["a", 1.23457, [1.0, 2.0]]]
    assert runs[1]["tables"][0]["rows"] == [["b", None]]
    assert runs[1]["headline"] == {"wall_s": {"min": 2.0, "max": 3.0}}
    assert {"cores", "load_average", "python", "numpy"} <= set(runs[1]["host"])


def test_record_writes_atomically(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    table = results.Table("t", ["case", "wall_s"], [["a", 1.0]])
    path = results.record("bench_x", [table], results_dir=tmp_path)
    before = path.read_bytes()

    with pytest.raises(TypeError):  # not serialisable: nothing written
        results.record(
            "bench_x", [results.Table("t", ["case", "wall_s"], [["b", object()]])],
            results_dir=tmp_path,
        )  # fmt: skip

    def half_written(doc, f, **kwargs) -> None:
        f.write('{"benchmark": "bench_x", "runs": [')
        raise OSError("disk full")

    monkeypatch.setattr(results.json, "dump", half_written)
    with pytest.raises(OSError, match="disk full"):
        results.record("bench_x", [table], results_dir=tmp_path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["bench_x.json"]  # no temporary left
    assert len(json.loads(path.read_text())["runs"]) == 1
