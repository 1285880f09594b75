"""Damaged outputs: deleted or altered chunks, truncated metadata, groups left incomplete.

The store reports them (naming stage, key, array and chunk), never reads them as zeros, and
the next run moves them aside and recomputes them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physanim.store import StageStore
from physanim.store.stage_store import QUARANTINE
from tests.commands import ROOT, TOY, invoke
from tests.conftest import COARSE
from tests.reliability.conftest import assert_store_tells_the_truth


def status(*args: str) -> dict[str, dict[str, str]]:
    out = invoke("status", *args, "--json")
    assert out.returncode == 0, out.stderr
    return {row["stage"]: row for row in json.loads(out.stdout)}


@pytest.fixture
def toy(toy_config: Path, tmp_path: Path) -> tuple[list[str], StageStore]:
    """The toy DAG run once by the CLI: (its -p/-c arguments, its store)."""
    args = ["-p", TOY, "-c", str(toy_config)]
    assert invoke("run", *args, "--local").returncode == 0
    return args, StageStore(tmp_path / "data" / "runs" / "store.zarr")


def test_deleted_and_altered_chunks_are_reported_and_recomputed(toy) -> None:
    args, store = toy
    source, scale = store.latest("source"), store.latest("scale")
    expected = store.open("scale")["scaled"][...]
    (store.root / "source" / source / "ramp" / "c" / "3" / "0").unlink()
    rows = status(*args)
    assert rows["source"]["action"] == "run" and rows["scale"]["action"] == "cached"
    assert rows["source"]["damaged"] == "array 'ramp' chunk c/3/0 is missing"
    show = invoke("show", "source", *args)
    assert show.returncode == 1 and "Traceback" not in show.stderr
    assert f"source/{source[:12]}" in show.stderr and "'ramp' chunk c/3/0 is missing" in show.stderr
    # the gesture: a downstream stage alone must not read the hole as zeros
    only = invoke("run", *args, "--local", "--only", "scale", "--force", "scale")
    assert only.returncode == 2
    assert "scale needs source: source is damaged (array 'ramp' chunk c/3/0" in only.stderr

    chunk = store.root / "scale" / scale / "scaled" / "c" / "0" / "0"
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2] ^= 0xFF  # same size: only the checksum can tell
    chunk.write_bytes(bytes(data))
    assert status(*args)["scale"]["action"] == "cached"
    rows = status(*args, "--verify")
    assert rows["scale"]["damaged"] == "array 'scaled' chunk c/0/0 does not match its checksum"
    verify = invoke("verify", *args)
    assert verify.returncode == 1 and "2 damaged" in verify.stdout

    fixed = invoke("run", *args, "--local", "--verify")
    assert fixed.returncode == 0, fixed.stderr
    assert f"source/{source[:12]} is damaged" in fixed.stderr and "moved to" in fixed.stderr
    assert f"scale/{scale[:12]} is damaged" in fixed.stderr
    assert invoke("verify", *args).returncode == 0
    np.testing.assert_array_equal(store.open("scale")["scaled"][...], expected)
    assert len([p for p in (store.root / QUARANTINE).iterdir() if p.is_dir()]) == 2
    cleaned = invoke("clean", *args)
    assert cleaned.stdout.count("removing quarantined") == 4  # two groups, two reasons
    assert_store_tells_the_truth(store)


def test_truncated_or_incomplete_metadata_is_never_a_dead_end(toy) -> None:
    args, store = toy
    total = store.root / "total" / store.latest("total") / "zarr.json"
    total.write_text(total.read_text()[:200])  # the group's own metadata, cut short
    scale_meta = store.root / "scale" / store.latest("scale") / "scaled" / "zarr.json"
    scale_meta.write_text(scale_meta.read_text()[:-40])  # an array's metadata, cut short
    rows = status(*args)
    assert rows["total"]["damaged"].startswith(f"metadata {total} is unreadable")
    assert rows["scale"]["damaged"].startswith("metadata scaled/zarr.json has ")
    show = invoke("show", "total", *args)
    assert show.returncode == 1 and str(total) in show.stderr and "Traceback" not in show.stderr
    # a group left with complete=false at its final path: --force and plain runs recover
    source = store.root / "source" / store.latest("source") / "zarr.json"
    meta = json.loads(source.read_text())
    meta["attributes"]["complete"] = False
    source.write_text(json.dumps(meta))
    assert status(*args)["source"]["damaged"].startswith("incomplete (complete=false)")
    dry = invoke("clean", *args, "--dry-run")
    assert dry.stdout.count("would remove damaged") == 3
    forced = invoke("run", *args, "--local", "--force", "source")
    assert forced.returncode == 0, forced.stderr
    assert invoke("verify", *args).returncode == 0
    assert float(store.open("total")["total"][0]) == pytest.approx(2 * (499500 * 8 + 1000 * 28))
    assert_store_tells_the_truth(store)


def test_deleted_chunk_of_a_face_output(face_copy: Path) -> None:
    """The issue's reproduction: a displacement chunk of simulate deleted.  ``status`` says
    damaged, ``--only evaluate --force evaluate`` refuses (no frames read as zeros) and a
    plain run recomputes simulate to the same displacements; evaluate's results stand."""
    store = StageStore(ROOT / face_copy / "runs" / "store.zarr")
    args = ["--dataset", str(face_copy), "-c", COARSE]
    rows = status(*args)
    key, evaluated = rows["simulate"]["key"], rows["evaluate"]["key"]
    before = store.open("simulate", key)["displacements"][...]
    cost = store.open("evaluate", evaluated)["fem/cost"][...]
    chunk = store.root / "simulate" / key / "displacements" / "c" / "0" / "0" / "0"
    chunk.unlink()
    rows = status(*args)
    assert rows["simulate"]["damaged"] == "array 'displacements' chunk c/0/0/0 is missing"
    refused = invoke("run", *args, "--local", "--only", "evaluate", "--force", "evaluate")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert "simulate is damaged (array 'displacements' chunk c/0/0/0 is missing)" in (
        refused.stderr
    )
    again = invoke("run", *args, "--local")
    assert again.returncode == 0, again.stderr
    assert "simulate: ran" in again.stderr and "evaluate: cached" in again.stderr
    np.testing.assert_allclose(store.open("simulate", key)["displacements"][...], before,
                               atol=1e-9)  # fmt: skip
    np.testing.assert_array_equal(store.open("evaluate", evaluated)["fem/cost"][...], cost)
    assert_store_tells_the_truth(store)


def test_an_output_made_from_a_since_replaced_input_is_stale(toy) -> None:
    """``--only S --force S`` of a stage whose result varies from run to run (fTetWild) left
    its downstream outputs cached under unchanged keys, computed from the old result (a face
    run then failed on mismatched node counts). Such outputs now read as stale: reported,
    refused as inputs, recomputed."""
    args, store = toy
    source, scale, total = (store.latest(s) for s in ("source", "scale", "total"))
    # a forced source that comes out different, as fTetWild's mesh does
    provenance = store.provenance("source", source)
    with store.writing("source", source, provenance, replace=True) as group:
        group["ramp"] = store.open("source", source)["ramp"][...] + 1.0
    rows = status(*args)
    assert rows["source"]["action"] == "cached" and not rows["source"]["damaged"]
    for stage in ("scale", "total"):  # total through scale
        assert rows[stage]["action"] == "run" and rows[stage]["damaged"].startswith(
            f"stale: computed from an earlier output of source ({source[:12]})"
        )
    only = invoke("run", *args, "--local", "--only", "total", "--force", "total")
    assert only.returncode == 2 and "total needs scale: scale is damaged (stale" in only.stderr
    again = invoke("run", *args, "--local")
    assert again.returncode == 0, again.stderr
    assert store.latest("scale") == scale and store.latest("total") == total
    expected = (store.open("source")["ramp"][...] * 2.0).sum()  # toy scale.factor is 2
    assert store.damage("scale", scale) is None and store.damage("total", total) is None
    assert float(store.open("total")["total"][0]) == pytest.approx(float(expected))
    assert_store_tells_the_truth(store)
