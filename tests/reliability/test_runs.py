"""Runs and what they leave: concurrent variants keep coherent sets, ``clean`` keeps the
upstream of everything the latest run and the report use."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

from flows.dags import FACE
from physanim.config import load_config
from physanim.pipeline import make_plan
from physanim.render.run_report import shown_variants
from physanim.store import StageStore
from tests.commands import ROOT, TOY, invoke, physanim_env, start
from tests.conftest import COARSE
from tests.reliability.conftest import assert_store_tells_the_truth


def test_concurrent_variant_runs_each_leave_a_coherent_set(
    toy_config: Path, tmp_path: Path
) -> None:
    """Two variants run at the same time (as model1 and model2 did in the issue): the latest
    run names one coherent set, and the other run's set is recorded beside it."""
    env = physanim_env(PHYSANIM_TOY_LOG=str(tmp_path / "executions.log"))
    args = ["run", "-p", TOY, "-c", str(toy_config), "--local", "--set", "source.slow_s=0.03"]
    procs = [start(*args, "--set", f"scale.factor={f}", env=env) for f in (2.0, 5.0)]
    outs = [p.communicate(timeout=120)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    runs = store.runs()
    assert len(runs) == 2 and len(store.keys("scale")) == 2 and len(store.keys("source")) == 1
    latest = runs[0]
    assert latest.name == store.latest_run_name()
    assert {s: store.latest(s) for s in latest.keys} == dict(latest.keys)
    factor = store.provenance("scale")["params"]["factor"]
    total = float(store.open("total")["total"][0])
    assert total == factor * (499500 * 8 + 1000 * 28)  # latest total is of the latest scale
    assert_store_tells_the_truth(store)


def test_clean_keeps_the_latest_and_reported_runs_with_their_upstream(
    toy_config: Path, tmp_path: Path
) -> None:
    """The issue's sequence on the toy DAG, then what clean does remove: outputs no kept run
    uses and the manifests of runs that are neither the latest nor complete."""
    args = ["-p", TOY, "-c", str(toy_config)]
    assert invoke("run", *args, "--local").returncode == 0
    assert invoke("run", *args, "--local", "--set", "source.n_frames=5").returncode == 0
    only = invoke("run", *args, "--local", "--only", "scale", "--set", "scale.factor=3")
    assert only.returncode == 0, only.stderr
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    frames = {r.name: store.provenance("source", r.keys["source"])["params"]["n_frames"]
              for r in store.runs()}  # fmt: skip
    five = next(r for r in store.runs() if frames[r.name] == 5)
    assert invoke("clean", *args).stdout.strip() == "nothing to clean"
    assert all(store.has(s, k) for s, k in five.keys.items())  # a complete run: reported
    again = invoke("run", *args, "--local")
    assert again.returncode == 0 and "0 stage(s) ran" in again.stderr
    scale3 = [
        k for k in store.keys("scale") if store.provenance("scale", k)["params"]["factor"] == 3
    ]
    cleaned = invoke("clean", *args)
    assert f"removing scale/{scale3[0][:12]}" in cleaned.stdout
    assert "(an incomplete run, not the latest)" in cleaned.stdout
    assert not store.has("scale", scale3[0]) and len(store.runs()) == 2
    assert all(store.has(s, k) for r in store.runs() for s, k in r.keys.items())
    assert_store_tells_the_truth(store)


def test_a_store_from_before_manifests_keeps_its_variants(toy_config: Path, tmp_path: Path) -> None:
    """Outputs without manifests and per-stage LATEST pointers (the earlier format) read as
    they are; the first clean or run records each final output's chain as a run, so clean
    keeps both variants and the report would show them."""
    args = ["-p", TOY, "-c", str(toy_config), "--local"]
    for factor in (2, 5):
        assert invoke("run", *args, "--set", f"scale.factor={factor}").returncode == 0
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    for stage in store.stages():  # back to the earlier format
        for key in store.keys(stage):
            meta = store.root / stage / key / "zarr.json"
            tree = json.loads(meta.read_text())
            del tree["attributes"]["manifest"]  # the earlier format had neither
            del tree["attributes"]["metadata_sha256"]
            meta.write_text(json.dumps(tree))
        (store.root / stage / "LATEST").write_text(store.latest(stage) + "\n")
    shutil.rmtree(store.root / ".runs")
    (store.root / "LATEST").unlink()
    assert store.provenance("scale")["params"]["factor"] == 5  # the per-stage pointer
    assert invoke("verify", *args[:-1]).returncode == 0
    assert invoke("clean", *args[:-1]).stdout.strip() == "nothing to clean"
    assert sorted(r.info["complete"] for r in store.runs()) == [True, True]
    assert len(store.keys("total")) == 2
    assert invoke("run", *args).returncode == 0  # factor 2: its adopted run becomes LATEST
    assert len(store.runs()) == 2 and store.provenance("scale")["params"]["factor"] == 2


def test_clean_after_variants_face_sequence(face_copy: Path) -> None:
    """The exact sequence of the issue on the coarse face demo: a run with
    align.refine_iterations=2, ``--only materials`` with another cheek radius, ``clean``, then
    a plain run, which must not crash; the report still shows the refine=2 variant."""
    args = ["--dataset", str(face_copy), "-c", COARSE, "--local"]
    refine = invoke("run", *args, "--set", "align.refine_iterations=2")
    assert refine.returncode == 0, refine.stderr
    only = invoke("run", *args, "--only", "materials", "--set", "materials.radius_cheek_m=0.013")
    assert only.returncode == 0, only.stderr
    files = [FACE.default_config, ROOT / COARSE]
    cfg, _ = load_config(FACE.config_model(), files, [f"dataset.dir={ROOT / face_copy}"])
    store = StageStore(cfg.dataset.store_path)
    refined_cfg, _ = load_config(
        FACE.config_model(), files, [f"dataset.dir={ROOT / face_copy}", "align.refine_iterations=2"]
    )
    refined = {e.stage: e.key for e in make_plan(FACE, refined_cfg, store)}
    cleaned = invoke("clean", "--dataset", str(face_copy), "-c", COARSE)
    assert cleaned.returncode == 0, cleaned.stderr
    assert all(store.has(s, k) for s, k in refined.items())  # materials of the refine=2 run too
    plain = invoke("run", *args[:-1])  # as typed: no --local (nothing to run: no Prefect)
    assert plain.returncode == 0, plain.stderr
    assert "0 stage(s) ran" in plain.stderr and "report:" in plain.stderr
    assert refined["evaluate"] in shown_variants(store, FACE.upstream("evaluate"))
    report = (ROOT / face_copy / "runs" / "report" / "index.html").read_text()
    assert re.search(rf"<th>uniform \({refined['simulate'][:6]}\)</th>", report)
    assert_store_tells_the_truth(store)
