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


@pytest.mark.parametrize("fill", ["random", "zeros"])
def test_damaged_colour_frame_in_a_bag_is_named(
    pristine: Pristine, tmp_path: Path, fill: str
) -> None:
    """A bag has no checksums: 6 KB of random bytes (or zeros) inside the colour image of
    frame 1 are found by the colour check and named (bag, frame, row), not passed on."""
    import numpy as np
    from rosbags.rosbag1 import Reader
    from rosbags.typesys import Stores, get_typestore

    from physanim.capture.frames import CaptureError
    from physanim.capture.ingest import CaptureWarning, load_capture
    from physanim.capture.params import IngestParams

    bag = pristine.copy("bag", tmp_path / "data")
    data = bytearray(bag.read_bytes())
    typestore = get_typestore(Stores.ROS1_NOETIC)
    with Reader(bag) as reader:
        (conn,) = [c for c in reader.connections if c.topic.endswith("Color_0/image/data")]
        raws = [raw for _, _, raw in reader.messages(connections=[conn])]
    pixels = bytes(typestore.deserialize_ros1(raws[1], conn.msgtype).data)
    middle = len(pixels) // 2
    offset = data.find(pixels[middle : middle + 4096])  # face rows: unique bytes
    assert offset > 0
    block = np.random.default_rng(1).bytes(6000) if fill == "random" else bytes(6000)
    data[offset : offset + 6000] = block
    bag.write_bytes(bytes(data))
    row = middle // (3 * 640)
    with pytest.raises(
        CaptureError,
        match=rf"capture\.bag: 1 damaged colour frame.*frame 1: \d+ pixels from row {row}",
    ):
        load_capture(bag)
    with pytest.warns(CaptureWarning, match=r"damaged colour frame.*kept as read"):
        load_capture(bag, IngestParams(implausible_depth="keep"))


def test_run_only_ingest_names_a_greyscale_frame(pristine: Pristine, tmp_path: Path) -> None:
    """`physanim run --only ingest` on an RGBD folder where one colour frame was re-exported
    in greyscale (accepted before: a grey frame among colour ones): one line naming it."""
    import cv2

    rgbd = pristine.copy("rgbd", tmp_path / "data")
    frame = rgbd / "color" / "000002.png"
    assert cv2.imwrite(str(frame), cv2.imread(str(frame), cv2.IMREAD_GRAYSCALE))
    out = invoke("run", "--only", "ingest", "--local", "--dataset", str(rgbd))
    text = out.stdout + out.stderr
    assert out.returncode == 1, text
    errors = [line for line in text.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, text
    assert "color/000002.png: a greyscale image among colour frames" in errors[0], errors
    assert "Traceback" not in out.stdout + out.stderr
