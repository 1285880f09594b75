"""A sweep on an existing Dask cluster, as the README starts one: ``dask scheduler`` and two
``dask worker --nthreads 1 --preload flows.worker_preload`` processes on 127.0.0.1 (started in
another folder than the sweep's), then ``physanim sweep FILE --dask-address tcp://...`` from the
repository root with relative paths. One worker is killed in the middle of a stage; a variant
fails. Every process started here is stopped by the fixture, within bounded waits.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from flows.dags import get_pipeline
from physanim.pipeline.sweep import plan_sweep
from tests.commands import ROOT, TOY, physanim, physanim_env, start
from tests.foundation.test_sweep import report_links_resolve
from tests.foundation.toy_stages import executions

DASK = str(Path(sys.executable).with_name("dask"))


def _stop(procs: list[subprocess.Popen]) -> None:
    """SIGTERM, then SIGKILL what is still running after 30 s."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
    deadline = time.time() + 30
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.time()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=10)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    """(scheduler address, toy execution log): a scheduler and two workers started by the
    README's commands in a folder outside the repository; stopped at the end.

    The sweep starts at once: it waits for the workers itself while its Prefect server starts.
    """
    from flows.prefect_env import free_port

    folder = tmp_path_factory.mktemp("cluster")
    address = f"tcp://127.0.0.1:{free_port()}"
    env = physanim_env(PHYSANIM_TOY_LOG=str(folder / "executions.log"))
    procs: list[subprocess.Popen] = []
    try:
        procs.append(
            subprocess.Popen(
                [DASK, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                 "--no-dashboard"],
                cwd=folder, env=env, stdout=(folder / "scheduler.log").open("w"),
                stderr=subprocess.STDOUT,
            )
        )  # fmt: skip
        for i in range(2):
            procs.append(
                subprocess.Popen(
                    [DASK, "worker", address, "--nthreads", "1", "--preload",
                     "flows.worker_preload", "--no-dashboard"],
                    cwd=folder, env=env, stdout=(folder / f"worker{i}.log").open("w"),
                    stderr=subprocess.STDOUT,
                )
            )  # fmt: skip
        yield address, folder
    finally:
        _stop(procs[::-1])


def _partial_output(store: Path, stage: str, key: str) -> tuple[Path, int] | None:
    """(folder, writer pid) of a half-written output of (stage, key), if one is there."""
    tmp = store / ".tmp"
    for p in tmp.glob(f"{stage}-{key[:16]}-*") if tmp.is_dir() else []:
        return p, int(p.name.split("-")[-2])
    return None


def test_sweep_on_an_existing_cluster_survives_a_killed_worker(
    cluster: tuple[str, Path], data_folder: Path
) -> None:
    address, folder = cluster
    data = data_folder / "toy"
    sweep = data_folder / "cluster.yaml"
    (ROOT / sweep).write_text(
        f"pipeline: {TOY}\ndatasets: [{data}]\nset: {{source.slow_s: 0.3}}\n"
        "grid: {scale.factor: [1.0, 2.0, 3.0]}\n"
        "variants: [{name: broken, set: {source.fail_at: 0}}]\n"
    )
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        plan = plan_sweep(sweep, get_pipeline)
    finally:
        os.chdir(cwd)
    slow_source = plan.keys["scale.factor=1.0"]["source"]
    proc = start("sweep", str(sweep), "--dask-address", address)
    try:
        deadline, found = time.time() + 240, None
        while found is None and time.time() < deadline and proc.poll() is None:
            time.sleep(0.2)
            found = _partial_output(ROOT / data / "runs" / "store.zarr", "source", slow_source)
        assert found is not None, f"the slow stage never started: {proc.stdout.read()[-3000:]}"
        time.sleep(1.0)  # a few frames in
        killed = found[1]
        os.kill(killed, signal.SIGKILL)  # the worker process (its nanny starts a new one)
        output, _ = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    # the failing variant is reported, the others complete (exit code 1 for the failure)
    error = "stage 'source' failed: ValueError: bad frame 0 (source.fail_at)"
    assert proc.returncode == 1, output[-3000:]
    assert f"error: variant 'broken': {error}" in output
    sweeps = ROOT / data / "runs" / "sweeps" / "cluster"
    summary = json.loads((sweeps / "summary.json").read_text())
    assert {v["variant"]: v["error"] for v in summary["variants"]} == {
        **{f"scale.factor={f}": None for f in ("1.0", "2.0", "3.0")},
        "broken": error,
    }
    base = 499500 * 8 + 1000 * 28
    totals = [v["summaries"]["total"]["total"] for v in summary["variants"][:3]]
    assert totals == pytest.approx([base, 2 * base, 3 * base])
    # each (stage, key) ran to completion once, on the workers (not the killed one)
    runs = [(r["stage"], r["key"]) for r in summary["runs"]]
    assert sorted(runs) == sorted({(j.entry.stage, j.entry.key) for j in plan.jobs} - {
        ("source", plan.keys["broken"]["source"]),
        ("scale", plan.keys["broken"]["scale"]),
        ("total", plan.keys["broken"]["total"]),
    })  # fmt: skip
    workers = {int(r["worker"].rsplit(":", 1)[1]) for r in summary["runs"]}
    assert killed not in workers and os.getpid() not in workers
    # the killed stage started twice (killed, then again elsewhere); everything else once
    ran = sorted(executions(folder))
    assert ran == ["scale"] * 3 + ["source"] * 3 + ["total"] * 3  # 2 slow + 1 broken source
    # the report is complete, its links resolve; the store is consistent
    report = sweeps / "index.html"
    links = report_links_resolve(report)
    assert "timeline.png" in links
    assert ">failed: " in report.read_text()
    assert not list((ROOT / data / "runs" / "store.zarr" / ".tmp").iterdir())
    verify = physanim("verify", "-p", TOY, "--dataset", str(data))
    assert verify.returncode == 0 and ", 0 damaged" in verify.stdout + verify.stderr, verify.stderr
