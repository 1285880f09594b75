"""Caching semantics of the stage runner on the toy DAG: what re-runs after which edit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pydantic import BaseModel, ConfigDict

from physanim.config import load_config
from physanim.pipeline import Pipeline, StageContext, StageSpec, execute_plan_locally, make_plan
from physanim.store import StageStore
from tests.commands import TOY, invoke
from tests.foundation.toy_stages import executions as ran
from tests.foundation.toy_stages import toy_pipeline


def run(pipe: Pipeline, cfg_file: Path, *sets: str, **sel) -> tuple[list[str], list[str]]:
    """Plan then execute; returns (stages the plan said would run, stages actually computed)."""
    config, _ = load_config(pipe.config_model(), [cfg_file], list(sets))
    store = StageStore(config.dataset.store_path)
    plan = make_plan(pipe, config, store, **sel)
    execute_plan_locally(pipe, config, plan)
    return [e.stage for e in plan if e.action == "run"], ran(cfg_file.parent)


def test_nothing_changed_reruns_nothing(toy_config: Path) -> None:
    pipe = toy_pipeline(toy_config)
    assert run(pipe, toy_config) == (["source", "scale", "total"],) * 2
    assert run(pipe, toy_config) == ([], [])


def test_param_edit_reruns_stage_and_downstream_only(toy_config: Path) -> None:
    pipe = toy_pipeline(toy_config)
    run(pipe, toy_config)
    planned, computed = run(pipe, toy_config, "scale.factor=3")
    assert planned == computed == ["scale", "total"]
    planned, computed = run(pipe, toy_config, "scale.factor=3", "source.n_frames=4")
    assert planned == computed == ["source", "scale", "total"]


def test_code_version_bump_reruns(toy_config: Path) -> None:
    run(toy_pipeline(toy_config), toy_config)
    planned, computed = run(toy_pipeline(toy_config, scale_version="2"), toy_config)
    assert planned == computed == ["scale", "total"]
    config, _ = load_config(toy_pipeline(toy_config).config_model(), [toy_config])
    store = StageStore(config.dataset.store_path)
    plan = make_plan(toy_pipeline(toy_config, "3"), config, store)
    assert "code version 2 -> 3" in plan[1].reason


def test_variants_coexist_and_both_read(toy_config: Path) -> None:
    pipe = toy_pipeline(toy_config)
    run(pipe, toy_config, "scale.factor=2")
    run(pipe, toy_config, "scale.factor=5")
    config, _ = load_config(pipe.config_model(), [toy_config])
    store = StageStore(config.dataset.store_path)
    keys = store.keys("total")
    assert len(keys) == 2 and len(store.keys("source")) == 1
    totals = sorted(float(store.open("total", k)["total"][0]) for k in keys)
    base = sum(np.arange(1000.0).sum() + 1000 * i for i in range(8))
    assert totals == pytest.approx([2 * base, 5 * base])
    assert float(store.open("total")["total"][0]) == pytest.approx(5 * base)  # latest
    # going back to the first variant is a pure cache hit that moves the latest pointer
    assert run(pipe, toy_config, "scale.factor=2") == ([], [])
    assert float(store.open("total")["total"][0]) == pytest.approx(2 * base)


def test_show_reads_the_output_of_the_configuration_it_is_given(toy_config: Path) -> None:
    """``physanim show`` with ``-c`` / ``--set`` shows that configuration's output, not the
    latest run's (a model-2 run after the default one must not answer for the default); with
    neither, the latest; a configuration not run yet is an error that says so."""
    args = ["-p", TOY, "-c", str(toy_config)]
    for factor in ("2.0", "3.0"):
        assert invoke("run", *args, "--local", "--set", f"scale.factor={factor}").returncode == 0

    def shown(*options: str) -> float:
        out = invoke("show", "scale", "-p", TOY, *options)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)["params"]["factor"]

    assert shown("-c", str(toy_config)) == 2.0  # the file's own factor, run first
    assert shown("-c", str(toy_config), "--set", "scale.factor=3.0") == 3.0
    assert shown("--dataset", str(toy_config.parent / "data")) == 3.0  # the latest
    missing = invoke("show", "scale", *args, "--set", "scale.factor=5.0")
    assert missing.returncode == 1 and "no output for this configuration yet" in missing.stderr


def test_status_matches_run_for_selections(toy_config: Path) -> None:
    pipe = toy_pipeline(toy_config)
    run(pipe, toy_config)
    assert run(pipe, toy_config, only="scale") == ([], [])
    assert run(pipe, toy_config, force=["scale"]) == (["scale", "total"],) * 2
    assert run(pipe, toy_config, start="total", force=["total"]) == (["total"], ["total"])
    planned, computed = run(pipe, toy_config, "scale.factor=7", only="scale")
    assert planned == computed == ["scale"]


def test_only_refuses_when_upstream_missing(toy_config: Path) -> None:
    pipe = toy_pipeline(toy_config)
    with pytest.raises(ValueError, match="needs source"):
        run(pipe, toy_config, only="scale")


class _SlowOnly(BaseModel):
    """The part of ``source``'s settings a stage sharing that section reads."""

    model_config = ConfigDict(extra="forbid")
    slow_s: float = 0.0


def _echo(ctx: StageContext) -> None:
    ctx.write("slow_s", np.array([ctx.params.slow_s]))  # type: ignore[attr-defined]


def test_a_stage_sharing_a_section_reads_its_fields_and_keys_on_them(toy_config: Path) -> None:
    """``section``: the stage takes the fields its params model declares from another stage's
    section (as ``tiles`` takes ``render``'s tile size); the config gains no section for it,
    and only those fields enter its key."""
    base = toy_pipeline(toy_config)
    echo = StageSpec("echo", ("source",), _SlowOnly, "1", _echo, section="source")
    pipe = Pipeline("toy", (*base.stages, echo), toy_config)
    assert "echo" not in pipe.config_model().model_fields
    planned, _ = run(pipe, toy_config, "source.slow_s=0.01")
    assert planned == ["source", "scale", "total", "echo"]
    store = StageStore(toy_config.parent / "data" / "runs" / "store.zarr")
    assert float(store.open("echo")["slow_s"][0]) == 0.01
    config, _ = load_config(pipe.config_model(), [toy_config], ["source.slow_s=0.01"])
    keys = {e.stage: e.key for e in make_plan(pipe, config, store)}
    assert echo.params_from(config) == _SlowOnly(slow_s=0.01)
    config, _ = load_config(pipe.config_model(), [toy_config], ["source.slow_s=0.02"])
    assert {e.stage: e.key for e in make_plan(pipe, config, store)}["echo"] != keys["echo"]
    wrong = StageSpec("echo", ("source",), _SlowOnly, "1", _echo, section="scale")
    with pytest.raises(ValueError, match=r"shares section 'scale'.*lacks \['slow_s'\]"):
        Pipeline("toy", (*base.stages, wrong), toy_config)
