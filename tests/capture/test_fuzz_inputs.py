"""Capture-input fuzzing, short form (issue #35): damaged colour and depth PNGs of an RGBD
folder, damaged stereo frames, bags, intrinsics JSON and stereo calibration YAML, each
ingested and judged by ``tests.capture.fuzz.judge`` (refused naming the file and field, or
accepted with the undamaged result). ``PHYSANIM_FUZZ_EXAMPLES=N`` runs N per kind (the long
form: ``python -m tests.capture.fuzz_long``)."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.commands import invoke

from .fuzz import KINDS, Pristine, judge

EXAMPLES = int(os.environ.get("PHYSANIM_FUZZ_EXAMPLES", "0"))
#: examples per kind in the short form (stereo and bag ingest take ~0.5 s each)
SHORT = {"colour PNG": 50, "depth PNG": 30, "stereo PNG": 16, "intrinsics JSON": 60,
         "calibration YAML": 30, "bag": 16}  # fmt: skip


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Pristine:
    """A 3-frame demo recording and its ingested sources."""
    return Pristine.make(tmp_path_factory.mktemp("fuzz") / "demo", n_frames=3)


@pytest.mark.parametrize("kind", list(KINDS))
def test_damaged_capture_inputs(kind: str, pristine: Pristine, tmp_path: Path) -> None:
    @settings(
        derandomize=True,
        database=None,
        deadline=None,
        max_examples=EXAMPLES or SHORT[kind],
        suppress_health_check=list(HealthCheck),
    )
    @given(seed=st.integers(0, 2**32 - 1))
    def check(seed: int) -> None:
        outcome = judge(pristine, kind, random.Random(seed), tmp_path / "work")
        assert not outcome.defect, outcome.line() + "\n" + outcome.message

    check()


def test_damaged_colour_frame_is_named_by_check(pristine: Pristine, tmp_path: Path) -> None:
    """`physanim check` on an RGBD folder whose colour frame is truncated: one error line
    naming the frame, exit status 1, no traceback."""
    rgbd = pristine.copy("rgbd", tmp_path / "data")
    frame = rgbd / "color" / "000001.png"
    frame.write_bytes(frame.read_bytes()[:5000])
    out = invoke("check", str(rgbd))
    assert out.returncode == 1, out.stdout
    errors = [line for line in out.stdout.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "color/000001.png: truncated at byte 5000" in errors[0], errors
    assert "Traceback" not in out.stdout + out.stderr
