"""Stereo depth on a real rectified pair with ground truth: Middlebury 2014 "Motorcycle"
(quarter size, shipped in scikit-image's wheel), and clear refusals of broken stereo input."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from physanim.capture.ingest import CaptureError, CaptureWarning, load_capture
from physanim.capture.params import IngestParams
from physanim.capture.stereo import StereoCalibration, StereoDepth

skdata = pytest.importorskip("skimage.data", reason="scikit-image (real stereo pair) missing")

# Calibration of the quarter-size pair (skimage.data.stereo_motorcycle's docstring).
FX, CX, CY, DOFFS, BASELINE = 994.978, 311.193, 254.877, 31.086, 0.193001


@pytest.fixture(scope="module")
def pair() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Left, right (500, 741, 3) uint8 and ground-truth disparity (500, 741) px (NaN: none)."""
    left, right, disp = skdata.stereo_motorcycle()
    return left, right, np.where(np.isfinite(disp), disp, np.nan).astype(np.float32)


def calibration(baseline: float) -> dict:
    """Plain-YAML calibration of the pair: K2's principal point is shifted by doffs."""
    k1 = [[FX, 0.0, CX], [0.0, FX, CY], [0.0, 0.0, 1.0]]
    k2 = [[FX, 0.0, CX + DOFFS], [0.0, FX, CY], [0.0, 0.0, 1.0]]
    return {
        "K1": k1, "D1": [0.0] * 5, "K2": k2, "D2": [0.0] * 5,
        "R": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "T": [-baseline, 0.0, 0.0],
        "image_width": 741, "image_height": 500, "fps": 30.0,
    }  # fmt: skip


def write_folder(root: Path, left: np.ndarray, right: np.ndarray, calib: dict) -> Path:
    for sub, img in (("left", left), ("right", right)):
        (root / sub).mkdir(parents=True, exist_ok=True)
        out = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
        assert cv2.imwrite(str(root / sub / "000000.png"), out)
    (root / "calibration.yaml").write_text(yaml.safe_dump(calib))
    return root


def score(disp: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(fraction of ground-truth pixels with a disparity, their median |error| px)."""
    has = np.isfinite(truth)
    ok = has & np.isfinite(disp)
    return ok.sum() / has.sum(), float(np.median(np.abs(disp[ok] - truth[ok])))


def test_accuracy_and_coverage_against_plain_sgbm(pair, tmp_path: Path) -> None:
    left, right, truth = pair
    path = tmp_path / "calibration.yaml"
    path.write_text(yaml.safe_dump(calibration(BASELINE)))
    calib = StereoCalibration.load(path)
    assert calib.is_rectified() and calib.doffs == pytest.approx(DOFFS)
    # The scene spans 2.1-5.0 m: search 2-5.5 m.
    rig = StereoDepth(calib, IngestParams(stereo_depth_range_m=(2.0, 5.5)), path)
    coverage, error = score(rig.disparity(left, right), truth)
    # Plain OpenCV SGBM over exactly the true disparity range, its own validity only.
    has = np.isfinite(truth)
    lo = int(np.floor(truth[has].min())) - 2
    n = 16 * -(-(int(np.ceil(truth[has].max())) + 2 - lo) // 16)
    sgbm = cv2.StereoSGBM_create(minDisparity=lo, numDisparities=n, blockSize=5, P1=600, P2=2400)
    raw = sgbm.compute(left, right)
    plain = np.where(raw > (lo - 1) * 16, raw / 16.0, np.nan)
    plain_coverage, plain_error = score(plain, truth)
    print(
        f"Motorcycle: ours {coverage:.1%} of ground-truth pixels at median {error:.3f} px; "
        f"plain SGBM {plain_coverage:.1%} at {plain_error:.3f} px"
    )
    assert coverage >= 0.80
    assert error <= plain_error
    # the sub-pixel refinement (physanim.capture.subpixel) against SGBM's own sub-pixel fit:
    # measured 0.178 -> 0.166 px (more steps drift on this pair: 4 steps 0.184 px)
    unrefined = StereoDepth(
        calib, IngestParams(stereo_depth_range_m=(2.0, 5.5), subpixel_iterations=0), path
    )
    _, unrefined_error = score(unrefined.disparity(left, right), truth)
    print(f"Motorcycle: SGBM's own sub-pixel fit {unrefined_error:.3f} px, refined {error:.3f} px")
    assert error < unrefined_error


def test_greyscale_pair_through_ingest(pair, tmp_path: Path) -> None:
    """Greyscale images and plain-YAML calibration; the baseline scaled by 1/5 puts the scene
    at 0.42-1.0 m (a face's distance) with the same disparities."""
    left, right, truth = pair
    grey = [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in (left, right)]
    root = write_folder(tmp_path / "stereo", *grey, calibration(BASELINE / 5))
    cap = load_capture(root, IngestParams(stereo_depth_range_m=(0.4, 1.1)))
    assert cap.color.shape == (1, 500, 741, 3) and cap.kind == "stereo" and cap.fps == 30.0
    assert (cap.color[0, ..., 0] == grey[0]).all()
    z_true = FX * BASELINE / 5 / (truth + DOFFS)
    coverage, _ = score(cap.depth[0], z_true)
    ok = np.isfinite(cap.depth[0]) & np.isfinite(z_true)
    rel = np.median(np.abs(cap.depth[0][ok] / z_true[ok] - 1))
    print(
        f"greyscale Motorcycle through ingest: {coverage:.1%} covered, median depth error {rel:.2%}"
    )
    assert coverage >= 0.75 and rel < 0.005


def test_swapped_pair_is_refused(pair, tmp_path: Path) -> None:
    left, right, _ = pair
    root = write_folder(tmp_path / "stereo", right, left, calibration(BASELINE / 5))
    with pytest.raises(
        CaptureError, match=r"stereo: left and right look swapped.*swap the folders"
    ):
        load_capture(root, IngestParams(stereo_depth_range_m=(0.4, 1.1)))


def test_depth_range_too_narrow_warns(pair, tmp_path: Path) -> None:
    left, right, _ = pair
    root = write_folder(tmp_path / "stereo", left, right, calibration(BASELINE / 5))
    with pytest.warns(CaptureWarning, match=r"far end of the searched depth range \(0\.7 m\)"):
        cap = load_capture(root, IngestParams(stereo_depth_range_m=(0.4, 0.7)))
    assert any("widen ingest.stereo_depth_range_m" in w for w in cap.warnings)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ({"T": [-193.001, 0.0, 0.0]}, r"T: baseline 193\.001 m is implausible.*millimetres"),
        ({"K1": [[FX, 0.0, CX], [0.0, FX, CY]]}, r"K1: expected 3x3 values, got shape \(2, 3\)"),
        ({"K2": [[FX, 0, 0], [0, FX, 0], [CX, CY, 1]]}, r"K2: not a camera matrix.*row by row"),
        ({"R": None}, r"stereo calibration lacks R; it needs K1, K2"),
        ({"image_width": "wide"}, r"image_width: expected a whole number of pixels.*got 'wide'"),
    ],
)
def test_bad_calibration_fields_are_named(pair, tmp_path: Path, edit: dict, message: str) -> None:
    left, right, _ = pair
    root = write_folder(tmp_path / "stereo", left, right, {**calibration(0.04), **edit})
    with pytest.raises(CaptureError, match=r"calibration\.yaml: " + message):
        load_capture(root)


def test_unparsable_calibration_names_file_and_line(demo_dir: Path, tmp_path: Path) -> None:
    """An OpenCV-written calibration with a broken line: one line naming file and position."""
    text = (demo_dir / "stereo" / "calibration.yaml").read_text().splitlines()
    text[5] = "   data: [ 615.1, 0., 322.3, : 0."
    path = tmp_path / "calibration.yaml"
    path.write_text("\n".join(text))
    with pytest.raises(CaptureError, match=r"calibration\.yaml: not valid YAML \(.* line 6"):
        StereoCalibration.load(path)
    calib = StereoCalibration.load(demo_dir / "stereo" / "calibration.yaml")
    assert calib.size == (480, 640) and calib.T[0] == pytest.approx(-0.06)


def test_left_right_size_mismatch_names_both(pair, tmp_path: Path) -> None:
    left, right, _ = pair
    root = write_folder(tmp_path / "stereo", left, right[:, :700], calibration(0.04))
    with pytest.raises(CaptureError, match=r"left and right images must have the same size"):
        load_capture(root, IngestParams(stereo_depth_range_m=(0.4, 1.1)))
