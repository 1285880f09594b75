"""Sweep report: which measures it shows, which media, and the timeline."""

from __future__ import annotations

import re
from pathlib import Path

from physanim.pipeline.runner import StageResult
from physanim.render.sweep_report import (
    SweepVariant,
    differing,
    measures,
    media,
    varying_stages,
    write_sweep_report,
)
from tests.render.plot_content import (
    assert_not_blank,
    capture_figures,
    colour_pixels,
    curve_drawn,
    read_rgb,
    to_pixels,
)


def _variant(name: str, sim_key: str, peak: float, files: dict[str, Path]) -> SweepVariant:
    return SweepVariant(
        name=name,
        dataset="demo",
        configs=(f"configs/models/{name}.yaml",),
        overrides=("dataset.name=demo",),
        keys={"tetra": "t0", "simulate": sim_key},
        summaries={
            "tetra": {"n_tets": 5000},
            "simulate": {"peak": peak, "seconds": {"step": 1.5}, "corner_mm": [1.0, 2.25]},
        },
        files=files,
    )


def test_only_differing_stages_and_measures_are_shown(tmp_path: Path) -> None:
    a, b = _variant("model1", "s1", 2.0, {}), _variant("model2", "s2", 3.0, {})
    assert varying_stages([a, b]) == ["simulate"]
    assert varying_stages([a]) == ["tetra", "simulate"]
    assert measures(a, ["simulate"]) == {
        "status": "complete",
        "dataset": "demo",
        "configs": "model1.yaml",
        "overrides": "dataset.name=demo",
        "simulate: peak": 2.0,
        "simulate: seconds.step": 1.5,
        "simulate: corner_mm": "1, 2.25",
    }
    shown = differing({v.name: measures(v, ["simulate"]) for v in (a, b)})
    assert shown == {
        "model1": {"configs": "model1.yaml", "simulate: peak": 2.0},
        "model2": {"configs": "model2.yaml", "simulate: peak": 3.0},
    }


def test_report_has_each_variants_media_and_a_timeline(tmp_path: Path, monkeypatch) -> None:
    saved = capture_figures(monkeypatch)
    variants = []
    for name in ("model1", "model2"):
        folder = tmp_path / name / "files"
        folder.mkdir(parents=True)
        for f in ("plot.png", "panel.mp4", "notes.txt"):
            (folder / f).write_bytes(b"x")
        variants.append(_variant(name, f"s_{name}", len(variants) + 1.0, {"simulate": folder}))
    assert [c for c, _ in media(variants[0], ["simulate"])] == [
        "simulate: panel.mp4",  # videos first; other files are left out
        "simulate: plot.png",
    ]
    results = [
        StageResult("tetra", "t0", "ran", 4.0, {}, 100.0, "host:1"),
        StageResult("simulate", "s_model1", "ran", 6.0, {}, 104.0, "host:1"),
        StageResult("simulate", "s_model2", "ran", 5.0, {}, 104.5, "host:2"),
    ]
    out = tmp_path / "report"
    page = write_sweep_report(
        out, title="Sweep t", variants=variants, results=results, seconds=11.0
    ).read_text()
    assert "<th>measure</th><th>model1</th><th>model2</th>" in page
    row = re.search(r"<tr><td>simulate: peak</td>(.*?)</tr>", page)
    assert row is not None and re.findall(r">([\d.]+)<", row.group(1)) == ["1", "2"]
    assert "n_tets" not in page.split("<h2>Per variant")[0]  # shared stage: not compared
    for name in ("model1", "model2"):
        assert f"src='../{name}/files/panel.mp4'" in page
        assert "notes.txt" not in page
    # the timeline: a bar per stage run, on its worker's lane, over its time span, coloured by
    # stage (tetra C0, simulate C1); nothing where no stage ran
    img = read_rgb(out / "timeline.png")
    assert_not_blank(img)
    fig = next(f for f, p in saved if p.name == "timeline.png")
    ax = fig.axes[0]
    for colour, lane, times in (("C0", 0, [1.0, 2.5, 3.5]), ("C1", 0, [6.0, 7.5, 9.5])):
        assert curve_drawn(img, fig, ax, times, [lane] * 3, colour, radius_px=1) == 1.0
    assert curve_drawn(img, fig, ax, [5.5, 7.5, 9.0], [1] * 3, "C1", radius_px=1) == 1.0
    for x, lane in ((2.0, 1), (10.5, 0), (10.2, 1)):  # worker 2 idle at 2 s; all done by 10.2 s
        rows, cols = to_pixels(img, fig, ax, [x], [lane])
        box = img[rows[0] - 2 : rows[0] + 3, cols[0] - 2 : cols[0] + 3]
        assert not (colour_pixels(box, "C0") | colour_pixels(box, "C1")).any(), (x, lane)
