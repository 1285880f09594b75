"""The fault-injection campaign in short (``campaign.py`` runs it long), and the defects it
found: partial outputs left in ``.tmp/`` by a failed write, damaged metadata that ``status``
did not name, a flipped bit in an output's own ``zarr.json`` that nothing noticed."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import zarr

from physanim.store import StageStore, write_array
from physanim.store.stage_store import TMP
from tests.commands import ROOT, TOY, invoke, physanim_env
from tests.reliability.campaign import (
    DAMAGE_KINDS,
    KINDS,
    TOY_STAGES,
    Campaign,
    layout_problems,
)
from tests.reliability.injector import inject


@pytest.mark.parametrize("kind", ["enospc", "eio", "rename"])
def test_a_failed_write_of_many_chunks_leaves_nothing_in_tmp(tmp_path: Path, kind: str) -> None:
    """One chunk write of an array fails while Zarr still writes the others: the temporary
    output is removed only once those have ended, so none of them recreates it."""
    store = StageStore(tmp_path / "store.zarr")
    for n in (3, 40, 150):
        with pytest.raises(OSError) as failed, inject(kind, n, store.root) as faults:
            with store.writing("big", f"{n:064d}", {}) as group:
                array = group.create_array("a", shape=(200, 500), dtype="f8", chunks=(1, 500))
                array[...] = np.random.default_rng(n).random((200, 500))
        assert faults.fired and str(store.root / TMP) in str(failed.value.filename)
        time.sleep(0.2)  # a straggling chunk write would have recreated it by now
        assert os.listdir(store.root / TMP) == [], (kind, n)
    assert store.all_keys("big") == []


def test_a_failed_commit_of_a_forced_output_puts_the_old_one_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--force``: the old output is moved aside, then the new one's rename fails (EIO): the
    old one goes back to its place (it was left in .tmp/ until the next run)."""
    store = StageStore(tmp_path / "store.zarr")
    key = "1" * 64
    final = store.root / "s" / key
    with store.writing("s", key, {}) as group:
        write_array(group, "a", np.arange(10.0))
    before = store.provenance("s", key)["manifest"]
    real = os.rename

    def failing(src: str | Path, dst: str | Path) -> None:
        if Path(dst) == store.root / "s" / key and not Path(src).name.startswith("replaced-"):
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(src))
        real(src, dst)

    monkeypatch.setattr(os, "rename", failing)
    with pytest.raises(OSError, match="Input/output error"):
        with store.writing("s", key, {}, replace=True) as group:
            write_array(group, "a", np.arange(10.0) + 1)
    monkeypatch.undo()
    assert store.has("s", key) and store.provenance("s", key)["manifest"] == before
    assert os.listdir(store.root / TMP) == [] and final.is_dir()


def test_a_full_disk_inside_a_stage_names_the_output_being_written(
    toy_config: Path, tmp_path: Path
) -> None:
    """ENOSPC on a chunk write inside a stage's compute (Zarr's error names no file): the one
    error line names the temporary output; nothing is left of it."""
    root = tmp_path / "data" / "runs" / "store.zarr"
    args = ["run", "-p", TOY, "-c", str(toy_config), "--local", "--set", "source.n_frames=30"]
    env = physanim_env(PHYSANIM_INJECT="enospc:25", PHYSANIM_INJECT_ROOT=str(root))
    full = subprocess.run(
        [sys.executable, "-m", "tests.reliability.injector", *args],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert full.returncode == 1 and "Traceback" not in full.stderr, full.stderr
    errors = [line for line in full.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, full.stderr
    head = f"error: stage 'source' failed: no space left writing {root}/.tmp/source-"
    assert errors[0].startswith(head), errors[0]
    assert "(No space left on device)" in errors[0]
    assert os.listdir(root / TMP) == []


def test_a_full_disk_when_recording_the_run_names_the_manifest(tmp_path: Path) -> None:
    store = StageStore(tmp_path / "store.zarr")
    with pytest.raises(OSError) as failed, inject("enospc", 1, store.root):
        store.record_run({"source": "0" * 64}, {})
    assert failed.value.filename is not None
    assert Path(failed.value.filename).parent == store.root / ".runs"
    assert os.listdir(store.root / ".runs") == []


def test_status_names_damaged_metadata_in_full(toy_config: Path, tmp_path: Path) -> None:
    """The probe's case: a complete output's zarr.json cut short; the table's column cuts a
    long path, so status also says it in one line."""
    args = ["-p", TOY, "-c", str(toy_config)]
    assert invoke("run", *args, "--local").returncode == 0
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    meta = store.root / "scale" / store.latest("scale") / "zarr.json"
    meta.write_text(meta.read_text()[:100])
    status = invoke("status", *args)
    assert status.returncode == 0
    assert f"damaged: scale/{meta.parent.name[:12]}: metadata {meta} is unreadable" in status.stdout
    chunk = store.root / "source" / store.latest("source") / "ramp" / "c" / "2" / "0"
    chunk.unlink()
    status = invoke("status", *args)
    line = f"damaged: source/{chunk.parents[3].name[:12]} ({chunk.parents[3]}): array 'ramp' "
    assert line + "chunk c/2/0 is missing" in status.stdout


def test_a_flipped_bit_in_an_outputs_metadata_is_found(toy_config: Path, tmp_path: Path) -> None:
    """An output's own zarr.json (its summary, provenance and manifest) is in no manifest;
    its checksum is in it, so a changed figure there is damage, not a silent wrong result."""
    args = ["-p", TOY, "-c", str(toy_config)]
    assert invoke("run", *args, "--local").returncode == 0
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    meta = store.root / "total" / store.latest("total") / "zarr.json"
    document = json.loads(meta.read_text())
    document["attributes"]["summary"]["total"] += 1.0  # still valid JSON, a wrong figure
    meta.write_text(json.dumps(document, indent=2))
    assert store.damage("total", meta.parent.name) == f"metadata {meta} does not match its checksum"
    verify = invoke("verify", *args)
    assert verify.returncode == 1 and f"metadata {meta} does not match" in verify.stdout
    fixed = invoke("run", *args, "--local")
    assert fixed.returncode == 0 and "total/" in fixed.stdout + fixed.stderr
    assert invoke("verify", *args).returncode == 0
    assert store.provenance("total")["summary"]["total"] == 2 * (499500 * 8 + 1000 * 28)


def test_unreadable_group_metadata_of_the_store_is_named_and_rewritten(
    toy_config: Path, tmp_path: Path
) -> None:
    """The store's and a stage's zarr.json hold an empty group: cut short, status names them,
    verify rewrites them (saying so) and the store opens as a Zarr group again."""
    args = ["-p", TOY, "-c", str(toy_config)]
    assert invoke("run", *args, "--local").returncode == 0
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    metas = [store.root / "zarr.json", store.root / "scale" / "zarr.json"]
    for meta in metas:
        meta.write_text(meta.read_text()[:7])
    status = invoke("status", *args)
    assert all(f"damaged: group metadata {m} is unreadable" in status.stdout for m in metas)
    verify = invoke("verify", *args)
    assert verify.returncode == 0, verify.stdout
    assert all(f"rewrote unreadable group metadata {m}" in verify.stdout for m in metas)
    assert store.damaged_groups() == [] and layout_problems(store) == []
    with warnings.catch_warnings():  # (.runs, .tmp and LATEST are not Zarr nodes)
        warnings.simplefilter("ignore")
        groups = set(zarr.open_group(store.root, mode="r").group_keys())
    assert groups == set(TOY_STAGES)


def test_verify_removes_what_a_killed_writer_left(toy_config: Path, tmp_path: Path) -> None:
    args = ["-p", TOY, "-c", str(toy_config)]
    assert invoke("run", *args, "--local").returncode == 0
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    dead = store.root / TMP / f"source-0123456789abcdef-{store._host}-999999999-0badf00d"
    (dead / "ramp").mkdir(parents=True)
    (dead / "ramp" / "zarr.json").write_text("{")
    verify = invoke("verify", *args)
    assert verify.returncode == 0, verify.stdout
    assert f"removed abandoned partial output {dead.name}" in verify.stdout
    assert not dead.exists() and layout_problems(store) == []


def test_short_campaign(tmp_path: Path) -> None:
    """Every kind of fault at least once on the toy DAG (16 in all, seeded): after each,
    nothing lost, nothing partial, outputs equal the undisturbed run's."""
    campaign = Campaign(tmp_path / "campaign", seed=35, verbose=False)
    campaign.run(toy_faults=16, face_faults=0)
    records = campaign.records
    failed = [(r.kind, r.detail, r.problems) for r in records if r.problems]
    assert failed == []
    assert {r.kind for r in records} == set(KINDS)
    assert sum(r.fired for r in records) >= 12
    damage = [r for r in records if r.kind in DAMAGE_KINDS and r.named_by_verify is not None]
    assert damage and all(r.named_by_verify and r.named_by_status for r in damage)
