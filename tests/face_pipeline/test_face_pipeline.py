"""The whole face DAG on a short demo, at coarse resolution: outputs, caching, physics.

Everything here runs the README's commands from the repository root with relative paths, as
a user types them: ``physanim run`` on a fresh coarse demo (session fixture ``face_demo``),
again with ``-c configs/models/model2.yaml`` (the material-model gesture, which must update
the report with both variants side by side), and ``physanim sweep`` of the shipped models.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from flows.dags import FACE
from physanim.config import load_config
from physanim.pipeline import make_plan
from physanim.store import StageStore
from tests.commands import ROOT, physanim
from tests.conftest import COARSE

RAN = re.compile(r"^(\w+): ran in", re.M)


def configure(data: Path, *files: str | Path, extra: tuple[str, ...] = ()):
    """Config and store of a coarse run on ``data`` (relative to the repository root)."""
    sets = [f"dataset.dir={ROOT / data}", *extra]
    files = [FACE.default_config, ROOT / COARSE, *(ROOT / f for f in files)]
    cfg, _ = load_config(FACE.config_model(), files, sets)
    return cfg, StageStore(cfg.dataset.store_path)


@pytest.fixture(scope="module")
def demo_run(face_demo):
    """The default (uniform material) run of the session's coarse demo."""
    data, out = face_demo
    cfg, store = configure(data)
    return data, cfg, store, RAN.findall(out)


@pytest.fixture(scope="module")
def model2_run(demo_run):
    """``physanim run -c configs/models/model2.yaml --set simulate.dt=0.002`` after the
    default run: the README's edit-and-rerun gesture (materials onward run again)."""
    data = demo_run[0]
    cmd = ["run", "--dataset", str(data), "-c", COARSE, "-c", "configs/models/model2.yaml"]
    out = physanim(*cmd, "--set", "simulate.dt=0.002")
    assert out.returncode == 0, out.stderr[-3000:]
    return data, out.stderr


@pytest.fixture(scope="module")
def model_sweep(model2_run):
    """The shipped models sweep (configs/sweeps/models.yaml) on the coarse demo, run by
    ``physanim sweep FILE --serial`` with a sweep file under data/ (relative paths)."""
    data = model2_run[0]
    sweep = data.parent / "models.yaml"
    (ROOT / sweep).write_text(
        (ROOT / "configs" / "sweeps" / "models.yaml")
        .read_text()
        .replace("datasets: [demo]", f"datasets: [{data}]")
        .replace(
            "variants:",
            f"configs: [{COARSE}]\nset: {{simulate.dt: 0.002, render.every_frames: 6}}\nvariants:",
        )
    )
    out = physanim("sweep", str(sweep), "--serial")
    assert out.returncode == 0, out.stderr[-3000:]
    folder = ROOT / data / "runs" / "sweeps" / "models"
    summary = json.loads((folder / "summary.json").read_text())
    keys = {v["variant"]: v["keys"] for v in summary["variants"]}
    return data, keys, RAN.findall(out.stderr), folder / "index.html"


def test_every_stage_runs_and_writes_its_outputs(demo_run) -> None:
    _, cfg, store, ran = demo_run
    assert ran == [s.name for s in FACE.stages]
    assert all(store.has(s.name, store.latest(s.name)) for s in FACE.stages)
    sim = store.open("simulate")
    n_frames = 12
    assert sim["displacements"].shape[0] == n_frames and sim["displacements"].dtype == np.float32
    d = sim["displacements"]
    assert d.chunks[1:] == d.shape[1:]  # chunked along frames only
    quality = store.provenance("tetra")["quality"]
    assert quality["min_dihedral_deg"] > 0 and quality["n_tets"] > 1000
    files = store.root / "render" / store.latest("render") / "files"
    video = cv2.VideoCapture(str(files / "panel.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 6  # every 2nd of 12 frames
    ok, frame = video.read()
    assert ok and frame.std() > 10 and frame.shape[1] > 4 * 120


def test_driven_nodes_follow_the_landmarks_and_the_skin_lags_between(demo_run) -> None:
    _, cfg, store, _ = demo_run
    aligned, mesh, sim = store.open("align"), store.open("tetra"), store.open("simulate")
    names = list(aligned.attrs["landmark_names"])
    driven = sim["driven_nodes"][...]
    disp = sim["displacements"][...]
    motion = aligned["motion"][...]
    landmark_node = mesh["landmark_node"][...]
    vertices = aligned["landmark_vertices"][...]
    for name in cfg.simulate.drive:
        i = names.index(name)
        node = landmark_node[i]
        assert node in driven
        expected = motion[:, vertices[i]] - motion[0, vertices[i]]
        np.testing.assert_allclose(disp[:, node], expected, atol=1e-6)  # m, float32 output
    # free skin moves (driven by elasticity) but less than the most-moving driven node
    skin = np.nonzero(mesh["skin"][...])[0]
    free = np.setdiff1d(skin, driven)
    peak_free = np.linalg.norm(disp[:, free], axis=-1).max()
    peak_driven = np.linalg.norm(disp[:, driven], axis=-1).max()
    assert 0 < peak_free <= 1.5 * peak_driven


def test_material_edit_reruns_materials_onward_only(model2_run) -> None:
    """The model overlay re-ran materials onward only, and the report (written from relative
    paths) shows both variants side by side with links that resolve."""
    data, out = model2_run
    assert RAN.findall(out) == ["materials", "simulate", "evaluate", "render"]
    report = ROOT / data / "runs" / "report" / "index.html"
    text = report.read_text()
    assert re.search(r"<th>measure</th><th>uniform \(\w+\)</th><th>model2 \(\w+\)</th>", text)
    assert "variants_symmetry.png" in text
    for link in re.findall(r"(?:src|href)='([^']+)'", text):
        assert (report.parent / link).is_file(), link
    edit = ("materials.model.regions.cphs_R.E_kPa=250.0",)  # a model no run used
    cfg, store = configure(data, "configs/models/model2.yaml", extra=edit)
    plan = make_plan(FACE, cfg, store)
    assert [e.stage for e in plan if e.action == "run"] == [
        "materials", "simulate", "evaluate", "render",
    ]  # fmt: skip


def test_regional_models_change_symmetry_as_physics_predicts(model_sweep) -> None:
    """A stiffer right philtrum (model 2) moves less on the right than model 1; softer (3) more.

    Measured on the free skin nodes of the cphs_R region against those of cphs_L.  The seed's
    right-side stretch E_R (eq 4.39, landmarks ex, pi, al, cphi around ch) must move
    monotonically with the cphs_R stiffness: models 2 and 3 fall on opposite sides of model 1.
    """
    data, variants, _, _ = model_sweep
    store = StageStore(ROOT / data / "runs" / "store.zarr")
    peak, stretch = {}, {}
    for model in ("model1", "model2", "model3"):
        keys = variants[model]
        mats = store.open("materials", keys["materials"])
        sim = store.open("simulate", keys["simulate"])
        names = list(mats.attrs["region_names"])
        tets = store.open("tetra", keys["tetra"])["tets"][...]
        labels = mats["tet_labels"][...]
        disp = np.linalg.norm(sim["displacements"][...], axis=-1)
        driven = sim["driven_nodes"][...]
        per_side = []
        for side in ("cphs_R", "cphs_L"):
            nodes = np.setdiff1d(np.unique(tets[labels == names.index(side)]), driven)
            per_side.append(disp[:, nodes].mean(axis=1).max())
        peak[model] = per_side[0] / per_side[1]  # right / left
        evaluated = store.open("evaluate", keys["evaluate"])
        stretch[model] = float(np.abs(evaluated["fem/e_right"][...]).max())
    print("right/left philtrum motion", peak, "max |E_R|", stretch)
    assert peak["model2"] < peak["model1"] < peak["model3"]
    assert (stretch["model2"] - stretch["model1"]) * (stretch["model3"] - stretch["model1"]) < 0


def test_model_sweep_computes_shared_stages_once(model_sweep, demo_run) -> None:
    """configs/sweeps/models.yaml: ingest..tetra and model2's materials..evaluate are the
    earlier runs' (cached), the rest runs once per model; the report shows the three models
    side by side, each with its own video."""
    data, keys, ran, report_path = model_sweep
    counts = {s.name: ran.count(s.name) for s in FACE.stages}
    assert counts == {
        "ingest": 0, "track": 0, "fit": 0, "align": 0, "tetra": 0,
        "materials": 2, "simulate": 2, "evaluate": 2, "render": 3,
    }  # fmt: skip
    store = StageStore(ROOT / data / "runs" / "store.zarr")
    assert list(keys) == ["model1", "model2", "model3"]
    default = {e.stage: e.key for e in make_plan(FACE, demo_run[1], store)}
    assert all(k[s] == default[s] for k in keys.values() for s in FACE.upstream("tetra"))
    for stage in FACE.upstream("tetra"):
        assert len({k[stage] for k in keys.values()}) == 1
    for stage in ("materials", "simulate", "evaluate", "render"):
        assert len({k[stage] for k in keys.values()}) == 3
        assert all(store.has(stage, k[stage]) for k in keys.values())
    report = report_path.read_text()
    assert "<th>measure</th><th>model1</th><th>model2</th><th>model3</th>" in report
    for k in keys.values():
        video = store.files("render", k["render"]) / "panel.mp4"
        assert int(cv2.VideoCapture(str(video)).get(cv2.CAP_PROP_FRAME_COUNT)) == 2  # 12 / 6
        assert os.path.relpath(video, report_path.parent.resolve()) in report
    # the sweep records its variants as runs but leaves the latest run (model2's) as it was
    cfg, _ = configure(data, "configs/models/model2.yaml", extra=("simulate.dt=0.002",))
    model2 = {e.stage: e.key for e in make_plan(FACE, cfg, store)}
    assert {s: store.latest(s) for s in model2} == model2
    assert {"model1", "model2", "model3"} <= {r.info.get("variant") for r in store.runs()}


def test_dag_upstream_and_downstream_closures() -> None:
    assert FACE.upstream("simulate") == [
        "ingest", "track", "fit", "align", "tetra", "materials", "simulate"
    ]  # fmt: skip
    assert FACE.upstream("tetra") == ["ingest", "track", "fit", "align", "tetra"]
    assert FACE.downstream("materials") == ["materials", "simulate", "evaluate", "render"]
    assert FACE.upstream("ingest") == ["ingest"]
