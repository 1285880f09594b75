"""A small three-stage DAG used by the foundation tests (never registered in the product).

``source`` makes a ramp, ``scale`` multiplies it, ``total`` sums it.  Each compute appends its
stage name to the file named by $PHYSANIM_TOY_LOG, so tests count real executions.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from physanim.pipeline import Pipeline, StageContext, StageSpec


def _log(name: str) -> None:
    log = os.environ.get("PHYSANIM_TOY_LOG")
    if log:
        with open(log, "a") as f:
            f.write(name + "\n")
        with open(log + ".threads", "a") as f:  # the worker's numba thread budget
            f.write(os.environ.get("NUMBA_NUM_THREADS", "unset") + "\n")


class SourceParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    n_frames: int = Field(8, ge=1, le=10_000, description="frames")
    slow_s: float = Field(0.0, ge=0.0, description="sleep between frames, s (for kill tests)")
    fail_at: int = Field(-1, description="raise ValueError at this frame (-1: never)")


class ScaleParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    factor: float = Field(2.0, gt=0.0, le=100.0, description="gain, dimensionless")


class TotalParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


def source(ctx: StageContext) -> None:
    _log("source")
    p: SourceParams = ctx.params  # type: ignore[assignment]
    arr = ctx.out.create_array("ramp", shape=(p.n_frames, 1000), dtype="f8", chunks=(1, 1000))
    report = ctx.progress("source")
    for i in range(p.n_frames):
        if i == p.fail_at:
            raise ValueError(f"bad frame {i} (source.fail_at)")
        arr[i] = np.arange(1000.0) + i
        report(i + 1, p.n_frames)
        time.sleep(p.slow_s)


def scale(ctx: StageContext) -> None:
    _log("scale")
    ramp = ctx.input("source")["ramp"][:]
    ctx.write("scaled", ramp * ctx.params.factor)  # type: ignore[attr-defined]


def total(ctx: StageContext) -> dict[str, float]:
    _log("total")
    ctx.write("total", np.array([ctx.input("scale")["scaled"][:].sum()]))
    return {"total": float(ctx.input("scale")["scaled"][:].sum())}


#: The toy DAG as the CLI addresses it: ``--pipeline tests.foundation.toy_stages:TOY``.
#: ``varies`` as fTetWild's mesh does (the toy's own output is the same every time): what is
#: computed from it goes stale when a test replaces it with different content
SOURCE = StageSpec("source", (), SourceParams, "1", source, varies=True)
SCALE = StageSpec("scale", ("source",), ScaleParams, "1", scale)
TOTAL = StageSpec("total", ("scale",), TotalParams, "1", total)


def executions(tmp_path: Path) -> list[str]:
    """Stage names computed since the last call (read from the toy log, which is then cleared)."""
    log = tmp_path / "executions.log"
    if not log.exists():
        return []
    names = log.read_text().split()
    log.unlink()
    return names


def toy_pipeline(default_config: Path, scale_version: str = "1") -> Pipeline:
    """The toy DAG, optionally with another code version of ``scale``."""
    scale_spec = StageSpec("scale", ("source",), ScaleParams, scale_version, scale)
    return Pipeline("toy", (SOURCE, scale_spec, TOTAL), default_config)


TOY = Pipeline("toy", (SOURCE, SCALE, TOTAL), Path(__file__).with_name("toy_default.yaml"))
