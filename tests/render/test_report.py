"""The HTML report: relative links to existing files, stage names, no external assets."""

from __future__ import annotations

import re

import numpy as np
import pytest

from physanim.render.panel import write_mp4
from physanim.render.plots import plot_symmetry_cost
from physanim.render.report import ReportError, build_report

STAGES = [
    "ingest", "track", "fit", "scan", "align", "tetra", "materials", "simulate", "evaluate",
    "render",
]  # fmt: skip


def test_report_links_and_content(tmp_path):
    out = tmp_path / "report"
    media = tmp_path / "media"
    video, _ = write_mp4([np.zeros((16, 16, 3), np.uint8)] * 3, media / "v.mp4", 30.0)
    png, _ = plot_symmetry_cost(np.arange(5.0), {"m1": np.zeros(5)}, media / "sym")
    stage_table = [
        dict(
            stage=s,
            key=f"k{i}",
            action="ran",
            seconds=0.5 * i,
            params={"dt": 1e-3},
            provenance={"code": "0.1.0"},
        )
        for i, s in enumerate(STAGES)
    ]
    path = build_report(
        out,
        title="Face <run>",
        video=video,
        images=[("symmetry cost", png)],
        key_figures={"peak ch_L (mm)": 3.14159, "frames": 3},
        stage_table=stage_table,
        variants={"model 1": {"cost": -4.0}, "model 2": {"cost": -3.5}},
    )
    assert path == out / "index.html"
    text = path.read_text()
    links = re.findall(r"(?:src|href)='([^']+)'", text)
    assert links, "no links found"
    for link in links:
        assert not link.startswith(("/", "http:", "https:", "file:"))
        assert (out / link).resolve().is_file(), link
    for s in STAGES:
        assert f"<details><summary>{s} " in text
    assert "Face &lt;run&gt;" in text  # escaped
    total = 0.5 * sum(range(len(STAGES)))  # the stages' seconds above
    assert "3.142" in text and "model 2" in text and f"Total: <b>{total:.2f} s</b>" in text
    assert "<script" not in text and "<link" not in text


def test_report_missing_file(tmp_path):
    with pytest.raises(ReportError, match="does not exist"):
        build_report(tmp_path, title="t", images=[("x", tmp_path / "nope.png")])


def test_relative_paths_are_relative_to_the_working_directory(tmp_path, monkeypatch):
    """The README's commands pass relative paths: ``out/x.png`` with ``out_dir=out`` is the
    file ``out/x.png``, linked as ``x.png`` (never ``out/out/x.png``)."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "runs" / "report"
    png, _ = plot_symmetry_cost(np.arange(5.0), {"m1": np.zeros(5)}, out / "sym")
    path = build_report("runs/report", title="t", images=[("cost", "runs/report/sym.png")])
    assert png == out / "sym.png" and "src='sym.png'" in path.read_text()


def test_run_report_compares_the_most_recent_variants_and_always_this_run():
    from physanim.render.run_report import recent_variants

    shown = [f"k{i}" for i in range(12)]  # oldest first, as the run manifests order them
    assert recent_variants(shown, "k11", 8) == shown[4:]
    # a run that recomputed nothing keeps its early place among the runs: still shown, last
    assert recent_variants(shown, "k2", 8) == [*shown[5:], "k2"]
    assert recent_variants(shown[:3], "k1", 8) == ["k0", "k2", "k1"]
    assert recent_variants(shown[:3], None, 2) == ["k1", "k2"]
    assert recent_variants(shown, "k0", 1) == ["k0"]


def test_warnings_open_the_report(tmp_path):
    """Stage warnings (a tracker that lost frames, figures that are NaN) come first, in a box
    of their own, escaped; without warnings there is no box."""
    lines = ["track: a face was found in only 57 of 90 frames (63%)", "fit: rms_mm is <NaN>"]
    text = build_report(tmp_path / "a", title="t", warnings=lines).read_text()
    box = text.index("<section class='card warnings'><h2>Warnings (2)</h2>")
    assert box < text.index("</header>") + 30 and "rms_mm is &lt;NaN&gt;" in text
    assert "Warnings" not in build_report(tmp_path / "b", title="t").read_text()


def test_the_capture_table_shows_the_simulated_facts_against_their_targets():
    """The report's physics rows read the simulate summary: the stress ratio, the tets turned
    inside out (in any frame, and at each peak from the evaluate summary) and the drive's
    share of the skin, each beside its target; and how many sampled scan vertices the errors
    leave out for want of a truth."""
    from physanim.render.run_report import capture_tables

    simulated = {"peak_to_p99_von_mises": 3.26, "inverted_tets": 60,
                 "spring_node_fraction_of_skin": 0.0}  # fmt: skip
    evaluated = {"fidelity": {"fem": {"worst": 0.2}, "kinematic": {"worst": 0.1}},
                 "inverted_tets_at_peaks": {"jaw_open": 58, "smile": 0},
                 "points_without_truth": {"scan": 1640, "sample": 262}}  # fmt: skip
    ((_, rows),) = capture_tables(evaluated, simulated).values()
    by_name = {row[0]: (row[1], row[3]) for row in rows}
    assert by_name["tets turned inside out (in any frame)"] == (60, "0")
    assert by_name["tets turned inside out at the jaw_open peak"] == (58, "0")
    assert by_name["tets turned inside out at the smile peak"] == (0, "0")
    assert by_name["peak / 99th-percentile von Mises stress (worst frame)"] == (3.26, "<= 5")
    (left_out,) = (row for row in rows if row[0].startswith("sampled scan vertices with no true"))
    assert left_out[1:] == [262, 262, ""]
