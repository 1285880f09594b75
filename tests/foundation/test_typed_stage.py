"""Adding a stage: output dataclass + compute + StageSpec + Pipeline, run by the real runner."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from pydantic import BaseModel

from physanim.pipeline import (
    Pipeline,
    StageOutput,
    StageSpec,
    execute_plan_locally,
    make_plan,
    stage_inputs,
)
from physanim.store import StageStore, read_dataclass


class RampParams(BaseModel):
    n: int = 5  # samples


class GainParams(BaseModel):
    gain: float = 3.0  # dimensionless


@dataclass(frozen=True)
class Ramp(StageOutput):
    values: np.ndarray  # (n,) m
    unit: str


def ramp(params: RampParams) -> Ramp:
    return Ramp(np.arange(float(params.n)), "m")


def gain(params: GainParams, ramp: Ramp) -> Ramp:
    values = ramp.values * params.gain
    return Ramp(values, ramp.unit, summary={"peak_m": float(values.max())})


STAGES = (StageSpec.typed("ramp", ramp, "1"), StageSpec.typed("gain", gain, "1"))
TWO = Pipeline("two", STAGES, default_config=Path("two.yaml"))


def test_toy_typed_stage_runs_through_the_runner_and_store(tmp_path):
    config = TWO.config_model().model_validate({"dataset": {"dir": str(tmp_path)}})
    store = StageStore(config.dataset.store_path)
    execute_plan_locally(TWO, config, make_plan(TWO, config, store))
    out = read_dataclass(Ramp, store.open("gain"))
    np.testing.assert_array_equal(out.values, [0.0, 3.0, 6.0, 9.0, 12.0])
    # the summary is part of the output: stored with it, read back with it
    assert out.summary == {"peak_m": 12.0} == store.provenance("gain")["summary"]
    assert read_dataclass(Ramp, store.open("ramp")).summary == {}
    assert out.unit == "m" and TWO.stage("gain").inputs == {"ramp": Ramp}
    assert "ramp -->|Ramp| gain" in TWO.mermaid() and "<- ramp: Ramp(values, unit)" in TWO.text()


def test_an_edge_whose_types_disagree_is_refused() -> None:
    def wrong(params: GainParams, ramp: GainParams) -> Ramp: ...

    def scaled(params: GainParams, ramp: Ramp) -> Scaled: ...

    def plain(params: GainParams) -> Plain: ...

    with pytest.raises(TypeError, match="ramp is annotated .*GainParams.*not a dataclass"):
        StageSpec.typed("wrong", wrong, "1")
    with pytest.raises(TypeError, match="must subclass StageOutput"):
        StageSpec.typed("plain", plain, "1")
    with pytest.raises(ValueError, match="total reads gain as Ramp, but gain stores Scaled"):
        stages = (*STAGES[:1], StageSpec.typed("gain", scaled, "1"))
        Pipeline("bad", (*stages, StageSpec.typed("total", total, "1")), Path("bad.yaml"))


@dataclass(frozen=True)
class Scaled(StageOutput):
    values: np.ndarray


@dataclass(frozen=True)
class Plain:
    values: np.ndarray


def total(params: GainParams, gain: Ramp) -> Ramp: ...


def test_stage_inputs_computes_what_is_missing_and_reads_it_typed(tmp_path):
    """``stage_inputs``: the typed outputs a stage reads, its upstream computed on demand."""
    config = TWO.config_model().model_validate({"dataset": {"dir": str(tmp_path)}})
    inputs = stage_inputs(TWO, config, "gain")
    assert list(inputs) == ["ramp"] and isinstance(inputs["ramp"], Ramp)
    np.testing.assert_array_equal(inputs["ramp"].values, [0.0, 1.0, 2.0, 3.0, 4.0])
    store = StageStore(config.dataset.store_path)
    planned = {e.stage: e.action for e in make_plan(TWO, config, store)}
    assert planned == {"ramp": "cached", "gain": "run"}  # only the upstream was computed


def test_nan_figures_of_a_summary_are_flagged(tmp_path):
    """A figure that could not be computed (NaN) becomes a warning naming it, through the
    runner: the CLI prints it and the report shows it at the top."""
    from physanim.pipeline.runner import flag_nan_figures

    nan = float("nan")
    flagged = flag_nan_figures({"rms": nan, "ok": 1.0, "inner": {"x": [1.0, nan]}})
    assert flagged["warnings"] == [
        "2 figure(s) of this stage are NaN (not computed): rms, inner.x[1]"
    ]
    assert flag_nan_figures({"ok": 1.0, "warnings": ["w"]}) == {"ok": 1.0, "warnings": ["w"]}

    def flat(params: GainParams, ramp: Ramp) -> Ramp:
        return Ramp(ramp.values, ramp.unit, summary={"mean_error_m": nan})

    pipeline = Pipeline(
        "nan", (STAGES[0], StageSpec.typed("flat", flat, "1")), default_config=Path("n.yaml")
    )
    config = pipeline.config_model().model_validate({"dataset": {"dir": str(tmp_path)}})
    store = StageStore(config.dataset.store_path)
    execute_plan_locally(pipeline, config, make_plan(pipeline, config, store))
    summary = store.provenance("flat")["summary"]
    assert summary["warnings"] == ["1 figure(s) of this stage are NaN (not computed): mean_error_m"]
