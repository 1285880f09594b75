"""docs/STAGES.md is generated from the stage declarations (``python -m flows.stage_docs``)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from flows import stage_docs
from physanim.pipeline import Pipeline, StageSpec
from tests.foundation.toy_stages import SCALE, SOURCE, TOTAL


def test_committed_stages_doc_is_up_to_date(tmp_path: Path) -> None:
    committed = stage_docs.OUT.read_text(encoding="utf-8")
    text = stage_docs.generate()
    assert committed == text, "docs/STAGES.md is out of date: run python -m flows.stage_docs"
    assert text == stage_docs.generate()  # deterministic
    for dag, stages in (
        ("face", ["ingest", "track", "fit", "scan", "align", "tetra", "materials", "simulate"]),
        ("keyframe", ["keyframes", "keyframe_render"]),
        ("arm", ["muscles", "arm_render"]),
    ):
        assert f"## {dag} DAG" in text
        assert all(f"\n### {s}\n" in text for s in stages), dag
    # --check: 1 on a stale file, 0 once written
    stale = tmp_path / "STAGES.md"
    stale.write_text(text.replace("### simulate", "### simulated"), encoding="utf-8")
    assert stage_docs.main(["--check", "-o", str(stale)]) == 1
    assert stage_docs.main(["-o", str(stale)]) == 0
    assert stage_docs.main(["--check", "-o", str(stale)]) == 0
    assert stale.read_text(encoding="utf-8") == text


class Spring(BaseModel):
    """One spring."""

    model_config = ConfigDict(extra="forbid")
    stiffness_N_per_m: float = Field(2e4, gt=0, le=1e6, description="spring stiffness, N/m")


class SpringParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    mode: str = Field("pull", description="what | the springs do")
    patch: Spring = Field(default_factory=Spring, description="the patch's spring")
    overrides: dict[str, Spring] = Field(default_factory=dict, description="per landmark")


@dataclass(frozen=True)
class Pull:
    """How far each node moved."""

    distance: np.ndarray
    names: list[str]


@dataclass(frozen=True)
class SpringsOutput:
    """The springs' pull: ``pull.distance`` (n,) m."""

    pull: Pull
    total_N: float


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _nothing(ctx) -> None:
    raise AssertionError("documenting a stage never runs it")


def test_toy_pipeline_doc_shows_fields_units_defaults_and_outputs(tmp_path: Path) -> None:
    config = tmp_path / "toy.yaml"
    config.write_text("dataset:\n  name: toy\nscale:\n  factor: 5.0\n", encoding="utf-8")
    springs = StageSpec(
        "springs", ("scale",), SpringParams, "3", _nothing, doc="pull skin patches",
        output=SpringsOutput,
    )  # fmt: skip
    raw = StageSpec("raw", ("springs",), NoParams, "1", _nothing)  # writes its group itself
    toy = Pipeline("toy", (SOURCE, SCALE, TOTAL, springs, raw), config)
    text = stage_docs.document([toy])

    assert "## toy DAG" in text
    assert "- [toy DAG](#toy-dag): source, scale, total, springs, raw" in text
    # the params model's fields: type, allowed range, default (the config file's), description
    assert "| `n_frames` | `int` | >= 1, <= 10000 | `8` | frames |" in text
    assert "| `slow_s` | `float` | >= 0.0 | `0.0` | sleep between frames, s (for kill" in text
    assert "| `factor` | `float` | > 0.0, <= 100.0 | `5.0` | gain, dimensionless |" in text
    # nested models flattened as dotted names; pipes escaped in the table
    assert '| `mode` | `str` |  | `"pull"` | what \\| the springs do |' in text
    assert "| `patch` | `Spring` |  | fields below | the patch's spring |" in text
    assert "| `patch.stiffness_N_per_m` | `float` | > 0, <= 1000000.0 | `20000.0` | spring" in text
    assert "| `overrides.<key>.stiffness_N_per_m` | `float` |" in text
    # the stage's version, upstream, doc, and its output dataclass with nested fields
    section = text[text.index("### springs") : text.index("### raw")]
    assert "version 3; upstream: [scale](#scale)." in section
    assert "Pull skin patches." in section
    assert "**Output** (`SpringsOutput`)" in section and "The springs' pull:" in section
    for row in ("| `pull` | `Pull` |", "| `pull.distance` | `np.ndarray` |",
                "| `pull.names` | `list[str]` |", "| `total_N` | `float` |"):  # fmt: skip
        assert row in section, row
    # a stage without params or a declared output dataclass says so
    section = text[text.index("### raw") :]
    assert "**Parameters** (`NoParams`; `--set raw.<name>=<value>`)\n\nNone." in section
    assert "the stage writes its group itself" in section


def test_changelog_says_why_every_stage_has_its_version() -> None:
    """CHANGELOG.md has a section for every stage of every DAG, and its newest line is the
    stage's current version: a version bump without its reason fails here."""
    from flows.dags import get_pipeline

    text = (stage_docs.OUT.parent.parent / "CHANGELOG.md").read_text(encoding="utf-8")
    for dag in ("face", "keyframe", "arm"):
        for spec in get_pipeline(dag).stages:
            head = f"\n### {spec.name}\n"
            assert head in text, f"CHANGELOG.md: no section for stage {spec.name}"
            section = text[text.index(head) + len(head) :].split("\n### ")[0]
            newest = re.search(r"^- \*\*(\d+)\*\*", section, re.M)
            assert newest and newest.group(1) == spec.version, (spec.name, spec.version)
