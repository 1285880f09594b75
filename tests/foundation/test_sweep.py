"""Sweeps: shared upstream stages run once; variants fan out on Dask workers through Prefect."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from physanim.config import ConfigError
from physanim.pipeline.sweep import load_sweep
from physanim.store import StageStore
from tests.commands import physanim, physanim_env
from tests.foundation.toy_stages import executions

ROOT = Path(__file__).resolve().parents[2]
TOY = "tests.foundation.toy_stages:TOY"


def test_expansion_grid_times_list(tmp_path: Path) -> None:
    f = tmp_path / "s.yaml"
    f.write_text(
        f"pipeline: {TOY}\ndatasets: [a, b]\nset: {{source.n_frames: 3}}\n"
        "grid: {scale.factor: [1, 2]}\nvariants: [{name: big, set: {scale.factor: 9}}]\n"
    )
    _, variants = load_sweep(f)
    assert [v.name for v in variants] == [
        "a:scale.factor=1", "a:scale.factor=2", "a:big",
        "b:scale.factor=1", "b:scale.factor=2", "b:big",
    ]  # fmt: skip
    assert variants[2].overrides == ("dataset.name=a", "source.n_frames=3", "scale.factor=9")
    f.write_text("grid: {scale.factor: 3}\n")
    with pytest.raises(
        ConfigError, match=r"s.yaml: grid.scale.factor: Input should be a valid list"
    ):
        load_sweep(f)


def test_worker_thread_env_shares_out_the_cores() -> None:
    from flows.dask_cluster import THREAD_ENV, worker_thread_env

    assert worker_thread_env(2, cores=2) == dict.fromkeys(THREAD_ENV, "1")
    assert worker_thread_env(1, cores=2)["NUMBA_NUM_THREADS"] == "2"
    assert worker_thread_env(3, cores=8)["OMP_NUM_THREADS"] == "2"
    assert worker_thread_env(4, cores=2)["OPENBLAS_NUM_THREADS"] == "1"


def test_sweep_on_dask_computes_shared_stage_once(toy_config: Path, tmp_path: Path) -> None:
    sweep = tmp_path / "sweep.yaml"
    data = tmp_path / "data"
    sweep.write_text(
        f"pipeline: {TOY}\ndatasets: [{data}]\ngrid: {{scale.factor: [1.0, 2.0, 3.0]}}\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    env.update(PYTHONPATH=str(ROOT), PHYSANIM_TOY_LOG=str(tmp_path / "executions.log"))
    cmd = [sys.executable, "-m", "cli", "sweep", str(sweep), "--workers", "2"]
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    ran = executions(tmp_path)
    assert sorted(ran) == ["scale"] * 3 + ["source"] + ["total"] * 3
    # each of the 2 local workers got half the cores for its numba / OpenMP / BLAS pools
    threads = set((tmp_path / "executions.log.threads").read_text().split())
    assert threads == {str(max(1, (os.cpu_count() or 1) // 2))}
    store = StageStore(tmp_path / "data" / "runs" / "store.zarr")
    totals = sorted(float(store.open("total", k)["total"][0]) for k in store.keys("total"))
    base = 499500 * 8 + 1000 * 28
    assert totals == pytest.approx([base, 2 * base, 3 * base])
    # the report puts the variants side by side with their own results, and times every run
    sweeps = tmp_path / "data" / "runs" / "sweeps" / "sweep"
    summary = json.loads((sweeps / "summary.json").read_text())
    runs = summary["runs"]
    assert sorted(r["stage"] for r in runs) == sorted(ran)
    assert all(r["started"] > 0 and r["seconds"] > 0 and r["worker"] for r in runs)
    report = (sweeps / "index.html").read_text()
    header = "<th>measure</th>" + "".join(
        f"<th>scale.factor={f}</th>" for f in ("1.0", "2.0", "3.0")
    )
    assert header in report
    row = re.search(r"<tr><td>total: total</td>(.*?)</tr>", report)
    assert row is not None
    cells = [float(c) for c in re.findall(r'<td class="num">([^<]+)</td>', row.group(1))]
    assert cells == pytest.approx([base, 2 * base, 3 * base], rel=1e-3)
    assert (sweeps / "timeline.png").stat().st_size > 1000 and "timeline.png" in report
    report_links_resolve(sweeps / "index.html")  # an absolute run directory


def report_links_resolve(report: Path) -> list[str]:
    """Every src/href of a report, after checking that each names an existing file relative
    to the report's folder (the links a browser opening it from disk follows)."""
    links = re.findall(r"(?:src|href)='([^']+)'", report.read_text())
    missing = [link for link in links if not (report.parent / link).is_file()]
    assert not missing, f"{report}: links to missing files {missing}"
    return links


def test_a_failing_variant_leaves_the_others_complete(data_folder: Path, tmp_path: Path) -> None:
    """The README's command, serially: the failing variant's error is in the report, the
    summary and the output (exit code 1); the other variants run to the end. Run again with
    a damaged output, the sweep quarantines it and computes it again."""
    sweep = data_folder / "fail.yaml"
    (ROOT / sweep).write_text(
        f"pipeline: {TOY}\ndatasets: [{data_folder / 'toy'}]\ngrid: {{scale.factor: [1.0, 2.0]}}\n"
        "variants: [{name: broken, set: {source.fail_at: 2}}]\n"
    )
    log = tmp_path / "executions.log"
    out = physanim("sweep", str(sweep), "--serial", env=physanim_env(PHYSANIM_TOY_LOG=str(log)))
    error = "stage 'source' failed: ValueError: bad frame 2 (source.fail_at)"
    assert out.returncode == 1, out.stderr[-3000:]
    assert f"error: variant 'broken': {error}" in out.stderr
    assert sorted(executions(tmp_path)) == ["scale"] * 2 + ["source"] * 2 + ["total"] * 2
    folder = ROOT / data_folder / "toy" / "runs" / "sweeps" / "fail"
    summary = json.loads((folder / "summary.json").read_text())
    assert {v["variant"]: v["error"] for v in summary["variants"]} == {
        "scale.factor=1.0": None,
        "scale.factor=2.0": None,
        "broken": error,
    }
    totals = [v["summaries"]["total"]["total"] for v in summary["variants"][:2]]
    base = 499500 * 8 + 1000 * 28
    assert totals == pytest.approx([base, 2 * base])
    report = folder / "index.html"
    status = re.search(r"<tr><td>status</td>(.*?)</tr>", report.read_text())
    assert status is not None
    assert re.findall(r"<td>([^<]*)</td>", status.group(1)) == [
        "complete",
        "complete",
        f"failed: {error}".replace("'", "&#x27;"),
    ]
    report_links_resolve(report)
    # again, with a chunk of the good variants' source lost: it is quarantined and recomputed
    store = StageStore(ROOT / data_folder / "toy" / "runs" / "store.zarr")
    key = summary["variants"][0]["keys"]["source"]
    chunks = (store.root / "source" / key / "ramp" / "c").rglob("*")
    next(p for p in chunks if p.is_file()).unlink()
    out = physanim("sweep", str(sweep), "--serial")
    assert out.returncode == 1 and f"source/{key[:12]} is damaged" in out.stderr
    assert re.findall(r"^(\w+): ran in", out.stderr, re.M) == ["source"]  # the rest cached
    assert len(store.quarantined()) == 2  # the group and its reason
    verify = physanim("verify", "-p", TOY, "--dataset", str(data_folder / "toy"))
    assert verify.returncode == 0, verify.stderr


def test_dask_address_without_a_scheduler_is_one_line() -> None:
    from flows.dask_cluster import connect
    from flows.prefect_env import free_port

    address = f"tcp://127.0.0.1:{free_port()}"
    with pytest.raises(ValueError, match=rf"^--dask-address {address}: no Dask scheduler answers"):
        connect(address, timeout_s=1.0)
