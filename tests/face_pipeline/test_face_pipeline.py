"""The whole face DAG on a short demo, at coarse resolution: outputs, caching, physics.

One module-scoped sweep of the shipped material models and the default run on its store
(12 frames, coarse scan and tets) feed every test here.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from flows.dags import FACE
from physanim.config import load_config
from physanim.pipeline import execute_plan_locally, make_plan
from physanim.store import StageStore

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
COARSE = [
    "demo.n_frames=12",
    "align.remesh_edge_length_m=0.0015",
    "tetra.surface_edge_length_m=0.005",
    "tetra.edge_length_m=0.007",
    "tetra.max_opt_iterations=5",
    "simulate.dt=0.002",
    "evaluate.error_every_frames=3",
    "evaluate.error_max_points=800",
    "render.tile_width_px=120",
    "render.tile_height_px=160",
    "render.every_frames=2",
]


def configure(data: Path, *files: Path, extra: tuple[str, ...] = ()):
    sets = [f"dataset.dir={data}", *COARSE, *extra]
    cfg, _ = load_config(FACE.config_model(), [FACE.default_config, *files], sets)
    return cfg, StageStore(cfg.dataset.store_path)


def run(cfg, store) -> list[str]:
    plan = make_plan(FACE, cfg, store)
    results = execute_plan_locally(FACE, cfg, plan)
    return [r.stage for r in results if r.action == "ran"]


@pytest.fixture(scope="module")
def model_sweep(tmp_path_factory: pytest.TempPathFactory):
    """The shipped models sweep (configs/sweeps/models.yaml) on a fresh coarse demo, serially."""
    from flows.sweep import run_sweep
    from tasks.ingest import ensure_demo

    tmp = tmp_path_factory.mktemp("face")
    data = tmp / "demo"
    ensure_demo(configure(data)[0])
    sets = "".join(f"\n  {k}: {v}" for k, v in (s.split("=", 1) for s in COARSE))
    sweep = tmp / "models.yaml"
    sweep.write_text(
        (CONFIGS / "sweeps" / "models.yaml")
        .read_text()
        .replace("datasets: [demo]", f"datasets: [{data}]")
        .replace("configs/models/", f"{CONFIGS}/models/")
        .replace("variants:", f"set:{sets}\n  render.every_frames: 6\nvariants:")
    )
    return data, run_sweep(sweep, serial=True)


@pytest.fixture(scope="module")
def demo_run(model_sweep):
    """The default (uniform material) run on the sweep's store: its shared stages are cached."""
    data, _ = model_sweep
    cfg, store = configure(data)
    ran = run(cfg, store)
    return data, cfg, store, ran


def test_every_stage_runs_and_writes_its_outputs(demo_run) -> None:
    _, cfg, store, ran = demo_run
    assert ran == ["materials", "simulate", "evaluate", "render"]  # upstream: the sweep's
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


def test_material_edit_reruns_materials_onward_only(demo_run) -> None:
    data, _, _, _ = demo_run
    edit = ("materials.model.regions.cphs_R.E_kPa=250.0",)  # a model the sweep did not run
    cfg, store = configure(data, CONFIGS / "models" / "model2.yaml", extra=edit)
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
    data, outcome = model_sweep
    store = StageStore(data / "runs" / "store.zarr")
    peak, stretch = {}, {}
    for model in ("model1", "model2", "model3"):
        keys = outcome.variants[model]
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


def test_model_sweep_computes_shared_stages_once(model_sweep) -> None:
    """configs/sweeps/models.yaml: ingest..tetra run once, materials onward once per model;
    the report shows the three models side by side, each with its own video."""
    data, outcome = model_sweep
    ran = [r.stage for r in outcome.results if r.action == "ran"]
    counts = {s.name: ran.count(s.name) for s in FACE.stages}
    assert counts == {
        "ingest": 1, "track": 1, "fit": 1, "align": 1, "tetra": 1,
        "materials": 3, "simulate": 3, "evaluate": 3, "render": 3,
    }  # fmt: skip
    store = StageStore(data / "runs" / "store.zarr")
    keys = outcome.variants
    assert list(keys) == ["model1", "model2", "model3"]
    for stage in FACE.upstream("tetra"):
        assert len({k[stage] for k in keys.values()}) == 1
    for stage in ("materials", "simulate", "evaluate", "render"):
        assert len({k[stage] for k in keys.values()}) == 3
        assert all(store.has(stage, k[stage]) for k in keys.values())
    report = outcome.report_path.read_text()
    assert "<th>measure</th><th>model1</th><th>model2</th><th>model3</th>" in report
    for k in keys.values():
        video = store.files("render", k["render"]) / "panel.mp4"
        assert int(cv2.VideoCapture(str(video)).get(cv2.CAP_PROP_FRAME_COUNT)) == 2  # 12 / 6
        assert os.path.relpath(video, outcome.report_path.parent.resolve()) in report


def test_dag_upstream_and_downstream_closures() -> None:
    assert FACE.upstream("simulate") == [
        "ingest", "track", "fit", "align", "tetra", "materials", "simulate"
    ]  # fmt: skip
    assert FACE.upstream("tetra") == ["ingest", "track", "fit", "align", "tetra"]
    assert FACE.downstream("materials") == ["materials", "simulate", "evaluate", "render"]
    assert FACE.upstream("ingest") == ["ingest"]
