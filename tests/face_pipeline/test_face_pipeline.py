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
from scipy.spatial.transform import Rotation

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
    """The default (uniform material) run of the session's coarse demo: (data, config, store,
    stages that ran, the run's output keys). Outputs are opened by key: other test modules run
    other variants on the same store, which moves its latest run."""
    data, out = face_demo
    cfg, store = configure(data)
    keys = {e.stage: e.key for e in make_plan(FACE, cfg, store)}
    return data, cfg, store, RAN.findall(out), keys


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
    # material outputs already in the store (other modules' variants may have made some)
    before = {}
    for model in ("model1", "model2", "model3"):
        cfg, store = configure(data, f"configs/models/{model}.yaml", extra=("simulate.dt=0.002",))
        key = {e.stage: e.key for e in make_plan(FACE, cfg, store)}["materials"]
        before[model] = store.has("materials", key)
    out = physanim("sweep", str(sweep), "--serial")
    assert out.returncode == 0, out.stderr[-3000:]
    folder = ROOT / data / "runs" / "sweeps" / "models"
    summary = json.loads((folder / "summary.json").read_text())
    keys = {v["variant"]: v["keys"] for v in summary["variants"]}
    return data, keys, RAN.findall(out.stderr), folder / "index.html", before


def test_every_stage_runs_and_writes_its_outputs(demo_run) -> None:
    _, cfg, store, ran, keys = demo_run
    assert ran == [s.name for s in FACE.stages]
    assert all(store.has(s.name, keys[s.name]) for s in FACE.stages)
    sim = store.open("simulate", keys["simulate"])
    n_frames = 12
    assert sim["displacements"].shape[0] == n_frames and sim["displacements"].dtype == np.float32
    d = sim["displacements"]
    assert d.chunks[1:] == d.shape[1:]  # chunked along frames only
    quality = store.provenance("tetra", keys["tetra"])["quality"]
    assert quality["min_dihedral_deg"] > 0 and quality["n_tets"] > 1000
    files = store.files("render", keys["render"])
    video = cv2.VideoCapture(str(files / "panel.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 6  # every 2nd of 12 frames
    ok, frame = video.read()
    assert ok and frame.std() > 10 and frame.shape[1] > 4 * 120


def test_skull_holds_the_mandible_turns_and_the_actuation_moves_the_skin(demo_run) -> None:
    """Bone-side nodes: fixed (skull) or turned exactly by the estimated jaw rotation
    (mandible); the jaw opens at the jaw-drop; the default drive (the fitted actuation) holds
    no skin node by a spring, and the skin moves by physics."""
    _, cfg, store, _, keys = demo_run
    mesh, sim = store.open("tetra", keys["tetra"]), store.open("simulate", keys["simulate"])
    nodes, disp = mesh["nodes"][...], sim["displacements"][...].astype(np.float64)
    bone, weight = sim["bone_nodes"][...], sim["mandible_weight"][...]
    assert np.array_equal(np.sort(bone), np.nonzero(mesh["bone"][...])[0])
    skull = bone[weight == 0]
    assert len(skull) > 100 and np.abs(disp[:, skull]).max() == 0.0
    angle, pivot, axis = (sim[f"jaw/{k}"][...] for k in ("angle", "pivot", "axis"))
    assert np.degrees(angle.max()) > 3.0  # the demo's jaw drop (11.5 deg at full opening)
    assert axis[0] > 0.95  # a left-right hinge
    turn = Rotation.from_rotvec(angle[:, None] * axis).as_matrix() - np.eye(3)
    expected = weight[None, :, None] * np.einsum("tij,kj->tki", turn, nodes[bone] - pivot)
    np.testing.assert_allclose(disp[:, bone], expected, atol=1e-6)  # m, float32 output
    # the chin's bone side turns fully: 23 of the fixed coarse mesh's 234 bone-side nodes
    # (9.8 %; 14 % on the full demo mesh)
    assert (weight == 1).sum() >= 0.08 * len(bone)
    skin = np.nonzero(mesh["skin"][...])[0]
    summary = store.provenance("simulate", keys["simulate"])["summary"]
    assert summary["drive"] == "actuation" and len(sim["spring_nodes"][...]) == 0
    # 82 % of the fixed coarse mesh's skin moves by more than 0.1 mm (the still brow does not)
    moving = np.linalg.norm(disp[:, skin], axis=-1).max(axis=0) > 1e-4
    assert moving.mean() > 0.75, moving.mean()


def test_the_simulated_face_performs_the_capture(demo_run) -> None:
    """Against the demo's ground truth, on the fixed coarse mesh (measured: the FEM mouth opens
    by 5.3 mm against the actor's 9.3 mm, as the 6 mm actuation patches span the 7 mm tets'
    lips; relative displacement error 0.121 at the jaw drop and 0.100 at the smile; peak /
    99th-percentile stress 2.30; the moved scan's silhouette against the truth's, worst frame,
    front / side: FEM 0.992 / 0.987): the mouth opens by at least 45 % of the actor's, the
    errors stay within 0.06 of those figures, no hot spot, no flap or tear in the outline.
    The fitted actuation's errors against the captured scan's and the springs':
    tests/face_pipeline/test_actuation_drive.py."""
    _, _, store, _, keys = demo_run
    summary = store.provenance("evaluate", keys["evaluate"])["summary"]
    evaluated = store.open("evaluate", keys["evaluate"])
    gap, fidelity = summary["lip_gap_mm"], summary["fidelity"]["fem"]
    opened = {m: gap[m]["jaw_open"] - evaluated[f"lip_gap_{m}"][0] * 1e3 for m in ("truth", "fem")}
    message = f"lip gap {gap}, opening {opened}, fidelity {fidelity}"
    print(message, "surfaces", summary["surfaces"])
    assert opened["truth"] > 3.0, message  # the actor's mouth opens by millimetres
    assert opened["fem"] > 0.45 * opened["truth"], message
    assert fidelity["jaw_open"]["overall"] < 0.18 and fidelity["smile"]["overall"] < 0.16, message
    stress = store.provenance("simulate", keys["simulate"])["summary"]["peak_to_p99_von_mises"]
    print("stress ratio", stress)
    assert stress <= 3.0, stress
    for variant in ("fem", "kinematic"):
        outline = summary["surfaces"][variant]["silhouette_iou_min"]
        assert min(outline.values()) >= 0.95, (variant, outline)


def test_material_edit_reruns_materials_onward_only(model2_run) -> None:
    """The model overlay re-ran materials onward only, and the report (written from relative
    paths) shows both variants side by side with links that resolve."""
    data, out = model2_run
    assert RAN.findall(out) == ["materials", "simulate", "evaluate", "render", "export"]
    report = ROOT / data / "runs" / "report" / "index.html"
    text = report.read_text()
    # the uniform run and this one (the newest, last); other modules' variants may sit between
    headers = re.findall(r"<tr><th>measure</th>(.*?)</tr>", text)
    variants = [h for h in headers if "model2" in h]
    assert len(variants) == 1, headers
    columns = re.findall(r"<th>([^<]*)</th>", variants[0])
    assert re.fullmatch(r"model2 \(\w+\)", columns[-1]), columns
    assert any(re.fullmatch(r"uniform \(\w+\)", c) for c in columns[:-1]), columns
    assert "variants_symmetry.png" in text
    for link in re.findall(r"(?:src|href)='([^']+)'", text):
        assert (report.parent / link).is_file(), link
    edit = ("materials.model.regions.cphs_R.E_kPa=250.0",)  # a model no run used
    cfg, store = configure(data, "configs/models/model2.yaml", extra=edit)
    plan = make_plan(FACE, cfg, store)
    assert [e.stage for e in plan if e.action == "run"] == [
        "materials", "simulate", "evaluate", "render", "export",
    ]  # fmt: skip


def test_regional_models_act_where_they_are_edited(model_sweep) -> None:
    """Models 1-3 differ only in the right philtrum (cphs_R: model 2 stiffer, model 3 softer).
    With the default drive (the fitted actuation, held) the right philtrum's motion follows
    its stiffness (model 2 < model 1 < model 3), and the edit acts there: model 3's change of
    each node's peak displacement from model 2's, averaged over the right philtrum's free
    nodes, is several times its average over the free nodes 20 mm or more from that region,
    and larger than the left philtrum's, which borders it. On the fixed coarse mesh: model 3's
    right philtrum peak +9.8 % over model 2's (asserted: 2.5 %, the landmark springs' +3.2 %),
    the mean node change +9.0 % there (asserted: 4 %), +6.9 % in the left philtrum, 0.31 % far
    away."""
    from physanim.names import name_index

    data, variants = model_sweep[:2]
    store = StageStore(ROOT / data / "runs" / "store.zarr")
    peak = {}
    for model in ("model1", "model2", "model3"):
        summary = store.provenance("evaluate", variants[model]["evaluate"])["summary"]
        peak[model] = summary["philtrum_peak_mm"]
    print("philtrum peaks (mm)", peak)
    assert peak["model2"]["right"] < peak["model1"]["right"] < peak["model3"]["right"]
    assert peak["model3"]["right"] / peak["model2"]["right"] - 1.0 >= 0.025

    keys = variants["model2"]
    mesh = store.open("tetra", keys["tetra"])
    nodes, tets = mesh["nodes"][:], mesh["tets"][:]
    materials = store.open("materials", keys["materials"])
    label = name_index(list(materials.attrs["region_names"]), ["cphs_R"])[0]
    sim = {m: store.open("simulate", variants[m]["simulate"]) for m in ("model2", "model3")}
    free = np.setdiff1d(np.arange(len(nodes)), sim["model2"]["driven_nodes"][:])
    moved = {m: np.linalg.norm(g["displacements"][:], axis=-1).max(axis=0) for m, g in sim.items()}
    change = moved["model3"] / np.maximum(moved["model2"], 1e-9) - 1.0
    region = np.intersect1d(np.unique(tets[materials["tet_labels"][:] == label]), free)
    far = np.linalg.norm(nodes - nodes[region].mean(axis=0), axis=1) >= 0.02
    far = free[far[free] & (moved["model2"][free] > 1e-4)]  # nodes that move at all
    near_change, far_change = change[region].mean(), np.abs(change[far]).mean()
    left = name_index(list(materials.attrs["region_names"]), ["cphs_L"])[0]
    left_nodes = np.intersect1d(np.unique(tets[materials["tet_labels"][:] == left]), free)
    left_change = change[left_nodes].mean()
    print(f"peak motion change: right philtrum {near_change:+.4f}, left {left_change:+.4f}, "
          f"20 mm away {far_change:.4f}")  # fmt: skip
    assert near_change >= 0.04 and near_change > 4 * far_change
    assert near_change > left_change + 0.01


def test_model_sweep_computes_shared_stages_once(model_sweep, demo_run) -> None:
    """configs/sweeps/models.yaml: ingest..tetra and model2's materials..evaluate are the
    earlier runs' (cached), the rest runs once per model; the report shows the three models
    side by side, each with its own video."""
    data, keys, ran, report_path, materials_before = model_sweep
    counts = {s.name: ran.count(s.name) for s in FACE.stages}
    assert materials_before["model2"]  # model2_run made it
    assert counts == {
        "ingest": 0, "track": 0, "fit": 0, "scan": 0, "align": 0, "tetra": 0,
        "tiles": 1,  # once for the three: the sweep renders every 6th frame
        "dense": 0, "actuate": 0,  # the material edits reuse the captured scan and actuation
        # model1's and model3's materials unless another module's variant made them
        "materials": sum(not materials_before[m] for m in ("model1", "model3")),
        "simulate": 2, "evaluate": 2, "render": 3, "export": 2,  # export reads simulate
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


def test_reduced_preview_of_a_model_against_its_full_run(model_sweep, demo_run) -> None:
    """``--set simulate.reduced.enabled=true`` previews model 3 in the POD basis of a full run
    of the uniform material, built by the preview itself (it reads no other output); measured
    here against model 3's full run of the sweep (4.1 % of the peak displacement on the fixed
    coarse mesh, 52 modes, under the actuation drive; 0.71-0.88 % under the landmark springs).
    The basis is cached: a second variant reuses it, and its residual estimate is reported
    per region."""
    from physanim.store import read_dataclass
    from tasks.simulate import SimulateOutput

    data = model_sweep[0]
    sets = ("simulate.reduced.enabled=true", "simulate.dt=0.002")  # the sweep's dt
    out = physanim("run", "--dataset", str(data), "-c", COARSE, "-c", "configs/models/model3.yaml",
                   "--only", "simulate", "--set", sets[0], "--set", sets[1])  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    cfg, store = configure(data, "configs/models/model3.yaml", extra=sets)
    keys = {e.stage: e.key for e in make_plan(FACE, cfg, store)}
    full_key = model_sweep[1]["model3"]["simulate"]
    assert keys["simulate"] != full_key  # its own content key
    summary = store.provenance("simulate", keys["simulate"])["summary"]
    reduced = summary["reduced"]
    print("reduced preview", reduced)
    assert reduced["basis_model"] == "uniform" and not reduced["basis_cached"]
    assert reduced["basis_error_peak_pct"] < 0.5 and 0 < reduced["modes"] <= 150
    assert summary["stepping"] == "reduced (POD preview)"
    preview = read_dataclass(SimulateOutput, store.open("simulate", keys["simulate"]))
    full = read_dataclass(SimulateOutput, store.open("simulate", full_key))
    error = np.abs(preview.displacements - full.displacements).max()
    peak = np.abs(full.displacements).max()
    assert 0 < error / peak < 0.05  # 4.1 % on the fixed coarse mesh (the actuation drive)
    # a stiffer uniform material, the whole pipeline: the basis is reused, the report made
    edit = (sets[0], "materials.model.default.E_kPa=300", "simulate.reduced.estimate=true")
    out = physanim("run", "--dataset", str(data), "-c", COARSE,
                   *(x for e in edit for x in ("--set", e)))  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    assert RAN.findall(out.stderr) == [
        "materials", "simulate", "evaluate", "render", "export",
    ]  # fmt: skip
    cfg, store = configure(data, extra=edit)
    keys = {e.stage: e.key for e in make_plan(FACE, cfg, store)}
    summary = store.provenance("simulate", keys["simulate"])["summary"]["reduced"]
    assert summary["basis_cached"] and summary["error"].startswith("estimate")
    by_region = summary["error_peak_pct_by_region"]
    assert max(by_region.values()) == pytest.approx(summary["error_peak_pct"], abs=1e-4)
    assert 0 < summary["error_peak_pct"] < 10.0  # 6.7 % on the fixed coarse mesh


def test_dag_upstream_and_downstream_closures() -> None:
    assert FACE.upstream("simulate") == [
        "ingest", "track", "fit", "scan", "align", "dense", "tetra", "materials", "actuate",
        "simulate",
    ]  # fmt: skip
    # the inverse step reads no materials: a material edit never runs it again
    assert "actuate" not in FACE.downstream("materials")
    assert FACE.upstream("tetra") == ["ingest", "track", "fit", "scan", "align", "tetra"]
    assert FACE.upstream("scan") == ["scan"]  # reads no stage: it runs beside ingest
    # the fit and captured-scan tiles render while the tissue is meshed; no material edit
    # renders them again
    assert FACE.upstream("tiles") == [
        "ingest", "track", "fit", "scan", "align", "dense", "tiles",
    ]  # fmt: skip
    assert "tiles" not in FACE.downstream("materials") and "tiles" in FACE.upstream("render")
    assert FACE.downstream("materials") == [
        "materials", "simulate", "evaluate", "render", "export",
    ]  # fmt: skip
    assert FACE.upstream("ingest") == ["ingest"]


@pytest.fixture(scope="module")
def seed_run(demo_run):
    """``physanim run -c configs/drives/seed.yaml``: the seed's 7 prescribed points, every
    bone-side node fixed (runs last: it moves the latest run)."""
    data = demo_run[0]
    out = physanim("run", "--dataset", str(data), "-c", COARSE, "-c", "configs/drives/seed.yaml")
    assert out.returncode == 0, out.stderr[-3000:]
    return configure(data, "configs/drives/seed.yaml")


def test_seed_drive_prescribes_its_points_and_keeps_the_mouth_shut(seed_run) -> None:
    """The seed's setting reproduces the thesis: each of the 7 points' nearest skin node
    follows its tracked landmark exactly, the bone side is fixed, and the mouth stays shut."""
    from physanim.face.drive import fill_gaps, head_frame

    cfg, store = seed_run
    keys = {e.stage: e.key for e in make_plan(FACE, cfg, store)}
    sim, tracked = store.open("simulate", keys["simulate"]), store.open("track", keys["track"])
    driving = list(sim.attrs["driving_landmarks"])
    assert sorted(driving) == sorted(cfg.simulate.drive.landmarks)
    disp = sim["displacements"][...]
    names = list(tracked.attrs["names"])
    traj, _ = fill_gaps(head_frame(tracked["points"][...], tracked["head_pose"][...]))
    nodes = sim["driven_nodes"][...][-len(driving) :]
    for name, node in zip(driving, nodes, strict=True):
        expected = traj[:, names.index(name)] - traj[0, names.index(name)]
        np.testing.assert_allclose(disp[:, node], expected, atol=1e-6)  # m, float32 output
    assert np.abs(disp[:, sim["bone_nodes"][...]]).max() == 0.0
    assert "jaw" not in sim
    gap = store.provenance("evaluate", keys["evaluate"])["summary"]["lip_gap_mm"]
    rest = store.open("evaluate", keys["evaluate"])["lip_gap_fem"][0] * 1e3
    assert gap["fem"]["jaw_open"] - rest < 0.3 * (gap["truth"]["jaw_open"] - rest)


def test_kinematic_target_drive_layers_physics_on_the_kinematic_scan(seed_run) -> None:
    """``-c configs/drives/kinematic.yaml`` (after the seed run, on the same store): every skin
    node with skin area is on a spring towards the kinematic scan, so the FEM skin moves about
    as well as the kinematic scan during the smile, and better than the seed's.

    fTetWild is not deterministic (even on one thread: 867-1021 nodes for this coarse mesh
    over four runs of one input), so the coarse FEM's smile error varies from run to run
    (0.31, 0.32 and 0.36 against the kinematic scan's 0.21-0.22 in three runs; the seed's
    0.89); the bound against the kinematic scan leaves room for that, the comparison with the
    seed is the sharp one."""
    seed_cfg, seed_store = seed_run
    seed_keys = {e.stage: e.key for e in make_plan(FACE, seed_cfg, seed_store)}
    seed = seed_store.provenance("evaluate", seed_keys["evaluate"])["summary"]["fidelity"]
    data = seed_run[0].dataset.path.relative_to(ROOT)
    out = physanim(
        "run", "--dataset", str(data), "-c", COARSE, "-c", "configs/drives/kinematic.yaml"
    )
    assert out.returncode == 0, out.stderr[-3000:]
    cfg, store = configure(data, "configs/drives/kinematic.yaml")
    keys = {e.stage: e.key for e in make_plan(FACE, cfg, store)}
    skin = store.open("tetra", keys["tetra"])["skin"][...]
    springs = store.open("simulate", keys["simulate"])["spring_nodes"][...]
    assert len(springs) > 0.8 * skin.sum()
    fidelity = store.provenance("evaluate", keys["evaluate"])["summary"]["fidelity"]
    print("kinematic drive fidelity", fidelity)
    smile = {m: fidelity[m]["smile"]["overall"] for m in ("fem", "kinematic")}
    smile["seed fem"] = seed["fem"]["smile"]["overall"]
    print("smile fidelity", smile)
    assert smile["fem"] < 0.5 * smile["seed fem"], smile
    assert smile["fem"] < smile["kinematic"] + 0.25, smile
