"""Ingest of the demo's three sources, and clear failures on broken recordings."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import zarr
from pydantic import ValidationError

from physanim.capture.ingest import Capture, CaptureError, find_source, load_capture
from physanim.capture.params import IngestParams

from .conftest import N_FRAMES


@pytest.fixture(scope="module")
def captures(demo_dir: Path) -> dict[str, Capture]:
    return {s: load_capture(demo_dir, IngestParams(source=s)) for s in ("bag", "rgbd", "stereo")}


def test_auto_detection_prefers_the_bag(demo_dir: Path) -> None:
    assert find_source(demo_dir) == ("bag", demo_dir / "capture.bag")
    assert find_source(demo_dir / "rgbd") == ("rgbd", demo_dir / "rgbd")


def test_sources_ingest_to_the_same_frames(captures: dict[str, Capture]) -> None:
    bag, rgbd, stereo = captures["bag"], captures["rgbd"], captures["stereo"]
    for cap in (bag, rgbd, stereo):
        np.testing.assert_array_equal(cap.frame_index, np.arange(N_FRAMES))
        np.testing.assert_allclose(cap.timestamps, np.arange(N_FRAMES) / 30.0, atol=1e-6)
        assert cap.color.shape == (N_FRAMES, 480, 640, 3) and cap.color.dtype == np.uint8
        assert cap.depth.dtype == np.float32 and cap.dropped == []
        np.testing.assert_allclose(cap.K, rgbd.K, atol=1e-4)
    np.testing.assert_array_equal(bag.color, rgbd.color)
    np.testing.assert_array_equal(stereo.color, rgbd.color)
    both = np.isfinite(bag.depth) & np.isfinite(rgbd.depth)
    assert both.sum() > 0.9 * np.isfinite(rgbd.depth).sum()
    assert np.abs(bag.depth[both] - rgbd.depth[both]).max() <= rgbd.depth_scale + 1e-6
    assert bag.depth_scale == pytest.approx(0.001) and rgbd.depth_scale == pytest.approx(0.001)
    print(f"bag: Open3D dropped {bag.recovered} (recovered), duplicated {bag.duplicated}")


def test_depth_matches_ground_truth(captures: dict[str, Capture], ground_truth: zarr.Group) -> None:
    truth = ground_truth["depth_true"][:]
    face = np.isfinite(truth)
    rgbd = captures["rgbd"].depth
    ok = face & np.isfinite(rgbd)
    assert np.median(np.abs(rgbd[ok] - truth[ok])) < 1.5e-3  # ~1 mm noise + 0.5 mm rounding
    stereo = captures["stereo"].depth
    ok = face & np.isfinite(stereo)
    err = np.median(np.abs(stereo[ok] - truth[ok]))
    valid = ok.sum() / face.sum()
    print(f"stereo depth: median |error| {err * 1e3:.2f} mm over {valid:.1%} of face pixels")
    assert err < 0.6e-3 and valid > 0.8  # 0.42 mm; SGBM without sub-pixel refinement 0.84 mm
    # Background (no texture) stays invalid instead of producing spurious depth.
    assert np.isfinite(stereo[~face]).mean() < 0.02


def test_validity_stats(captures: dict[str, Capture]) -> None:
    cap = captures["rgbd"]
    np.testing.assert_allclose(cap.valid_fraction, np.isfinite(cap.depth).mean(axis=(1, 2)))
    assert np.all((cap.depth_median > 0.4) & (cap.depth_median < 0.6))


def test_truncated_bag_fails_clearly(demo_dir: Path, tmp_path: Path) -> None:
    data = (demo_dir / "capture.bag").read_bytes()
    bad = tmp_path / "truncated.bag"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(CaptureError, match=r"truncated\.bag: unreadable or truncated"):
        load_capture(bad)


def copy_dataset(demo_dir: Path, tmp_path: Path, sub: str) -> Path:
    dst = tmp_path / sub
    shutil.copytree(demo_dir / sub, dst)
    return dst


def test_missing_depth_frame_fails_clearly(demo_dir: Path, tmp_path: Path) -> None:
    rgbd = copy_dataset(demo_dir, tmp_path, "rgbd")
    (rgbd / "depth" / "000002.png").unlink()
    with pytest.raises(CaptureError, match=r"color/000002\.png: no matching depth frame 000002"):
        load_capture(rgbd)


def test_gaps_are_reported_or_refused(demo_dir: Path, tmp_path: Path) -> None:
    rgbd = copy_dataset(demo_dir, tmp_path, "rgbd")
    for sub in ("color", "depth"):
        (rgbd / sub / "000001.png").unlink()
    cap = load_capture(rgbd, IngestParams(max_missing_fraction=0.2))
    assert cap.dropped == [1] and cap.frame_index.tolist() == [0, 2, 3, 4, 5]
    np.testing.assert_allclose(cap.timestamps, [0, 2 / 30, 3 / 30, 4 / 30, 5 / 30])
    with pytest.raises(CaptureError, match="1 of 6 frames missing.*max_missing_fraction=0.1"):
        load_capture(rgbd, IngestParams(max_missing_fraction=0.1))


def test_size_mismatch_and_pixel_format_fail_clearly(demo_dir: Path, tmp_path: Path) -> None:
    rgbd = copy_dataset(demo_dir, tmp_path, "rgbd")
    cv2.imwrite(str(rgbd / "depth" / "000003.png"), np.zeros((240, 320), np.uint16))
    with pytest.raises(CaptureError, match=r"000003\.png is 640x480 but .*000003\.png is 320x240"):
        load_capture(rgbd)
    cv2.imwrite(str(rgbd / "depth" / "000003.png"), np.zeros((480, 640), np.uint8))
    with pytest.raises(CaptureError, match=r"depth/000003\.png: unsupported depth pixel format"):
        load_capture(rgbd)


def test_stereo_without_calibration_fails_clearly(demo_dir: Path, tmp_path: Path) -> None:
    stereo = copy_dataset(demo_dir, tmp_path, "stereo")
    (stereo / "calibration.yaml").unlink()
    with pytest.raises(CaptureError, match=r"calibration\.yaml: missing stereo calibration"):
        load_capture(stereo)


def test_stereo_rectifies_an_unrectified_calibration(demo_dir: Path, tmp_path: Path) -> None:
    """A calibration given with a tiny rotation is rectified and still gives face depth."""
    stereo = copy_dataset(demo_dir, tmp_path, "stereo")
    fs = cv2.FileStorage(str(stereo / "calibration.yaml"), cv2.FILE_STORAGE_READ)
    K, T = fs.getNode("K1").mat(), fs.getNode("T").mat()
    fs.release()
    fs = cv2.FileStorage(str(stereo / "calibration.yaml"), cv2.FILE_STORAGE_WRITE)
    for key, val in {
        "K1": K,
        "D1": np.zeros((1, 5)),
        "K2": K,
        "D2": np.zeros((1, 5)),
        "R": cv2.Rodrigues(np.array([0.0, 1e-4, 0.0]))[0],
        "T": T,
    }.items():
        fs.write(key, val)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.release()
    for sub in ("left", "right"):
        for f in sorted((stereo / sub).glob("*.png"))[1:]:
            f.unlink()
    cap = load_capture(stereo)
    assert "rectified here" in cap.source and cap.fps == 30.0
    assert 0.45 < np.nanmedian(cap.depth[0]) < 0.55


def test_params_validation() -> None:
    with pytest.raises(ValidationError, match="odd"):
        IngestParams(block_size=4)
    with pytest.raises(ValidationError):
        IngestParams(stereo_depth_range_m=(1.0, 0.5))
    with pytest.raises(ValidationError):
        IngestParams(unknown=1)
