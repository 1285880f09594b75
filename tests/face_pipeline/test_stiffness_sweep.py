"""The shipped stiffness sweep (configs/sweeps/stiffness.yaml: a grid over one nested value,
``materials.model.default.E_kPa``) end to end on the session's coarse demo, by the README's
command from the repository root: ``physanim sweep FILE --serial``.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from flows.dags import FACE
from physanim.config import load_config
from physanim.pipeline import make_plan
from physanim.store import StageStore
from tests.commands import ROOT, physanim
from tests.conftest import COARSE
from tests.foundation.test_sweep import report_links_resolve

GRID_KPA = (96.2, 192.4, 384.8)
RAN = re.compile(r"^(\w+): ran in", re.M)


@pytest.fixture(scope="module")
def stiffness_sweep(face_demo):
    """(dataset dir, summary.json, stages that ran, report path) of the shipped stiffness
    sweep on the coarse demo (a copy of the file under data/ naming that demo)."""
    data, _ = face_demo
    sweep = data.parent / "stiffness.yaml"
    text = (ROOT / "configs" / "sweeps" / "stiffness.yaml").read_text()
    assert "datasets: [demo]" in text
    (ROOT / sweep).write_text(
        text.replace("datasets: [demo]", f"datasets: [{data}]\nconfigs: [{COARSE}]")
    )
    out = physanim("sweep", str(sweep), "--serial")
    assert out.returncode == 0, out.stderr[-3000:]
    folder = ROOT / data / "runs" / "sweeps" / "stiffness"
    summary = json.loads((folder / "summary.json").read_text())
    return data, summary, RAN.findall(out.stderr), folder / "index.html"


def test_each_variant_has_its_own_stiffness_and_the_rest_of_the_default(stiffness_sweep) -> None:
    data, summary, ran, _ = stiffness_sweep
    store = StageStore(ROOT / data / "runs" / "store.zarr")
    variants = summary["variants"]
    assert [v["variant"] for v in variants] == [
        f"materials.model.default.E_kPa={e}" for e in GRID_KPA
    ]
    for e_kpa, v in zip(GRID_KPA, variants, strict=True):
        assert v["error"] is None
        mats = store.open("materials", v["keys"]["materials"])
        np.testing.assert_array_equal(mats["E"][...], e_kpa * 1e3)  # Pa, every tet
        np.testing.assert_array_equal(mats["nu"][...], 0.495)  # the uniform model's others
        np.testing.assert_array_equal(mats["eta"][...], 476.8)
    # E = 192.4 kPa is the default config itself: that variant reuses the demo run's outputs
    files = [FACE.default_config, ROOT / COARSE]
    default, _ = load_config(FACE.config_model(), files, [f"dataset.dir={ROOT / data}"])
    keys = {e.stage: e.key for e in make_plan(FACE, default, store)}
    assert variants[1]["keys"] == keys
    assert ran.count("materials") == 2 and ran.count("tetra") == 0
    assert ran.count("simulate") == ran.count("evaluate") == ran.count("render") == 2


def test_stiffer_tissue_carries_higher_stress(stiffness_sweep) -> None:
    """Driven by the same motion (jaw turned, landmarks pulled), stress grows with E."""
    _, summary, _, _ = stiffness_sweep
    peaks = [v["summaries"]["simulate"]["peak_von_mises_kPa"] for v in summary["variants"]]
    assert peaks == sorted(peaks) and peaks[0] < peaks[-1], peaks


def test_report_compares_the_three_stiffnesses(stiffness_sweep) -> None:
    _, _, _, report = stiffness_sweep
    page = report.read_text()
    header = "<th>measure</th>" + "".join(
        f"<th>materials.model.default.E_kPa={e}</th>" for e in GRID_KPA
    )
    assert header in page
    assert "<td>simulate: peak_von_mises_kPa</td>" in page
    report_links_resolve(report)
