"""``physanim check``: what a dataset holds, or each problem with its fix, on the demo, on a
dataset made from a real photo (scikit-image's astronaut) and on broken variants of it."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from physanim.capture.params import IngestParams
from physanim.tracking.dataset_check import CheckReport, check_dataset
from physanim.tracking.params import TrackParams

from .photo_dataset import FX, write_photo_dataset

pytest.importorskip("ai_edge_litert", reason="markerless extra not installed")
skdata = pytest.importorskip("skimage.data", reason="scikit-image (real test photo) missing")

ROOT = Path(__file__).resolve().parents[2]
MARKERLESS = TrackParams(backend="markerless")


def facts(report: CheckReport) -> dict[str, str]:
    return dict(report.facts)


def errors(report: CheckReport) -> list[str]:
    return [p.message for p in report.problems if p.level == "error"]


def test_demo_is_reported_without_problems(demo_dir: Path) -> None:
    report = check_dataset(demo_dir, IngestParams(), TrackParams(), demo_dir / "ground_truth.zarr")
    found = facts(report)
    print("\n".join(report.lines()))
    assert report.ok and report.problems == []
    assert found["source"].startswith("RealSense bag capture.bag")
    assert found["frames"].startswith("6 at 30 fps")
    assert found["resolution"] == "640x480 px"
    assert found["intrinsics"].startswith("fx 615.1, fy 615.4, cx 322.3, cy 241.6 px")
    assert "nearest surface at the centre 0.48 m; scale 1000 units/m" in found["depth"]
    assert found["markers"].startswith("36 dots in frame 0")
    assert " of 6 frames" in found["face"]


def test_cli_on_a_real_photo_dataset_and_a_broken_one() -> None:
    """The README's command, from the repository root with a relative dataset path."""
    rel = Path("data") / f"pytest-{os.getpid()}-check"
    try:
        write_photo_dataset(ROOT / rel / "me", skdata.astronaut())
        write_photo_dataset(ROOT / rel / "coffee", skdata.coffee())
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        ok, bad = (
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "cli",
                    "check",
                    f"{rel}/{name}",
                    "--set",
                    "track.backend=markerless",
                ],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                timeout=120,
            )  # fmt: skip
            for name in ("me", "coffee")
        )
    finally:
        shutil.rmtree(ROOT / rel, ignore_errors=True)
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.startswith(f"{rel}/me:\n  source      Open3D RGBD folder {rel}/me")
    assert (
        "face        found in 4 of 4 frames" in ok.stdout and "ok: no problems found" in ok.stdout
    )
    assert bad.returncode == 1
    assert f"error: {rel}/coffee: no face found in any of the 4 frames" in bad.stdout
    assert "Traceback" not in bad.stdout + bad.stderr


def test_photo_dataset_facts(tmp_path: Path) -> None:
    root = write_photo_dataset(tmp_path / "me", skdata.astronaut())
    report = check_dataset(root, IngestParams(), MARKERLESS)
    found = facts(report)
    assert report.problems == [], report.lines()
    assert found["frames"] == "4 at 30 fps (0.1 s; 0 missing)"
    assert found["intrinsics"] == "fx 500.0, fy 500.0, cx 256.0, cy 256.0 px (54 deg)"
    assert "nearest surface at the centre 0.6" in found["depth"]
    assert found["face"].startswith("found in 4 of 4 frames")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (  # 0.25 mm depth units and no depth_scale: the face is read 2.4 m away
            {"depth_unit_m": 0.00025, "depth_scale_in_json": False},
            r"nearest surface at the image centre is 2\.5\d m away with depth_scale 1000 "
            r"units/m, not a face's 0\.2-2 m: depth_scale wrong\? set depth_scale",
        ),
        (  # the same at 0.45 m: 1.8 m is a plausible distance, but the face is 3x too large
            {"distance_m": 0.45, "depth_unit_m": 0.00025, "depth_scale_in_json": False},
            r"the face comes out 3\.\d\d x the size of the face model: the depth scale or the "
            r"intrinsics are wrong \(RGBD folder: depth_scale",
        ),
        (
            {"intrinsics": {"intrinsic_matrix": [FX, 0, 256, 0, FX, 256, 0, 0, 1]}},
            r"intrinsic\.json: intrinsic_matrix: looks row-major",
        ),
        (
            {"intrinsics": {"fx": 2.0, "fy": 2.0, "cx": 256, "cy": 256}},
            r"fx = 2 px gives a 179 deg field of view on 512 px wide images",
        ),
        (
            {"intrinsics": {"fx": FX, "fy": FX, "cx": 640, "cy": 360}},
            r"principal point \(640, 360\) px lies outside the 512x512 image",
        ),
    ],
)
def test_broken_photo_datasets(tmp_path: Path, kwargs: dict, message: str) -> None:
    root = write_photo_dataset(tmp_path / "me", skdata.astronaut(), **kwargs)
    report = check_dataset(root, IngestParams(), MARKERLESS)
    assert not report.ok
    assert any(re.search(message, e) for e in errors(report)), errors(report)


def test_broken_depth_and_missing_template(tmp_path: Path) -> None:
    root = write_photo_dataset(tmp_path / "me", skdata.astronaut())
    report = check_dataset(root, IngestParams(), TrackParams(), root / "ground_truth.zarr")
    (err,) = errors(report)  # markers backend: no template (the face is still found)
    assert "marker template not found; for a recording without painted markers set " in err
    assert "track.backend=markerless" in err and facts(report)["face"].startswith("found in 4")
    for f in (root / "depth").glob("*.png"):
        cv2.imwrite(str(f), np.zeros((512, 512), np.uint16))
    report = check_dataset(root, IngestParams(), MARKERLESS)
    (err,) = errors(report)
    assert err.startswith(f"{root}: no valid depth in any of the 4 frames (all zero or invalid)")


def test_missing_dataset_and_recording(tmp_path: Path) -> None:
    report = check_dataset(tmp_path / "nothing", IngestParams(), MARKERLESS)
    assert errors(report) == [f"{tmp_path / 'nothing'}: dataset not found"]
    (tmp_path / "empty").mkdir()
    (err,) = errors(check_dataset(tmp_path / "empty", IngestParams(), MARKERLESS))
    assert "no recording found; looked for a RealSense *.bag file or an RGBD folder" in err
    assert "see the README section 'Your own recording'" in err
