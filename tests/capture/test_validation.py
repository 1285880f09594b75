"""Ingest refuses or flags nonsense: intrinsics forms, depth frames that cannot be surfaces
(a damaged bag: ROS1 bags carry no checksums), depth spikes between frames."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Reader
from rosbags.typesys import Stores, get_typestore

from physanim.capture.frames import Capture, CaptureError
from physanim.capture.ingest import CaptureWarning, load_capture
from physanim.capture.intrinsics import check_camera_matrix, parse_intrinsics
from physanim.capture.params import IngestParams
from physanim.capture.validate import implausible_depth_frames

from .conftest import N_FRAMES

FX, FY, CX, CY = 600.0, 610.0, 320.0, 240.0
K = np.array([[FX, 0.0, CX], [0.0, FY, CY], [0.0, 0.0, 1.0]])
SIZE = {"width": 640, "height": 480}


@pytest.mark.parametrize(
    "entries",
    [
        {"intrinsic_matrix": [FX, 0, 0, 0, FY, 0, CX, CY, 1]},  # Open3D, column-major
        {"intrinsic_matrix": [[FX, 0, CX], [0, FY, CY], [0, 0, 1]]},  # rows
        {"fx": FX, "fy": FY, "cx": CX, "cy": CY},
        {"fx": FX, "fy": FY, "ppx": CX, "ppy": CY},  # RealSense's names
    ],
)
def test_accepted_intrinsics_forms(entries: dict) -> None:
    K_read, size = parse_intrinsics({**SIZE, **entries}, Path("intrinsic.json"))
    np.testing.assert_array_equal(K_read, K)
    assert size == (480, 640)


@pytest.mark.parametrize(
    ("entries", "message"),
    [
        ({"intrinsic_matrix": [FX, 0, CX, 0, FY, CY, 0, 0, 1]}, r"M: looks row-major.*column"),
        ({"intrinsic_matrix": [[FX, 0, 0], [0, FY, 0], [CX, CY, 1]]}, r"M: .*of columns.*rows"),
        ({"intrinsic_matrix": [FX, 0, 0, 0, FY, 0, CX, CY]}, r"M: expected 9 numbers or 3 rows"),
        ({"fx": FX, "fy": FY}, r"no intrinsic_matrix and no cx, cy; write"),
        ({"fx": "600", "fy": FY, "cx": CX, "cy": CY}, r"fx: expected a number \(px\)"),
    ],
)
def test_refused_intrinsics_name_the_field(entries: dict, message: str) -> None:
    message = message.replace("M: ", "intrinsic_matrix: ")
    with pytest.raises(CaptureError, match=r"intrinsic\.json: " + message):
        parse_intrinsics({**SIZE, **entries}, Path("intrinsic.json"))


def test_camera_matrix_plausibility() -> None:
    assert check_camera_matrix(K, (480, 640), "x") == []
    tiny = K.copy()
    tiny[0, 0] = tiny[1, 1] = 1.93  # a focal length in mm, not px
    (err,) = check_camera_matrix(tiny, (480, 640), "x")
    assert err.level == "error" and "179 deg field of view" in err.message
    other = K * [[2], [2], [1]]  # intrinsics of 1280x960 images
    (err,) = check_camera_matrix(other, (480, 640), "x")
    assert err.level == "error" and "outside the 640x480 image" in err.message


def frames_capture(depth: np.ndarray) -> Capture:
    t = len(depth)
    return Capture(
        color=np.zeros((*depth.shape, 3), np.uint8), depth=depth.astype(np.float32), K=K,
        depth_scale=0.001, timestamps=np.arange(t) / 30.0, frame_index=np.arange(t), fps=30.0,
        source="test",
    )  # fmt: skip


def test_depth_spikes_are_flagged_but_motion_and_cuts_are_not() -> None:
    rng = np.random.default_rng(1)
    base = 0.5 + 0.002 * rng.standard_normal((10, 48, 64))
    base[:, :, :20] = np.nan
    closer = base * np.linspace(1.0, 0.7, 10)[:, None, None]  # moving 15 cm closer in 1/3 s
    assert implausible_depth_frames(frames_capture(closer)) == {}
    cut = base.copy()
    cut[5:] *= 2.0  # the scene changes for good: not a spike
    assert implausible_depth_frames(frames_capture(cut)) == {}
    spike = base.copy()
    spike[4] *= 3.0
    spike[7, :, :20] = 0.5  # a third more valid pixels for one frame
    bad = implausible_depth_frames(frames_capture(spike))
    assert sorted(bad) == [4, 7]
    assert "median depth 1.50 m" in bad[4] and "valid pixels 100%" in bad[7]
    noise = base.copy()
    noise[2] = rng.uniform(0.2, 60.0, noise[2].shape)  # random bytes read as depth
    assert "of neighbouring pixels jump" in implausible_depth_frames(frames_capture(noise))[2]


@pytest.fixture(scope="module")
def damaged_bag(demo_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo bag with 200 KB of random bytes written inside the depth image of frame 3."""
    src = demo_dir / "capture.bag"
    data = bytearray(src.read_bytes())
    typestore = get_typestore(Stores.ROS1_NOETIC)
    with Reader(src) as reader:
        (conn,) = [c for c in reader.connections if c.topic.endswith("Depth_0/image/data")]
        raws = [raw for _, _, raw in reader.messages(connections=[conn])]
    pixels = bytes(typestore.deserialize_ros1(raws[3], conn.msgtype).data)
    middle = len(pixels) // 2
    offset = data.find(pixels[middle : middle + 8192])  # face rows: unique bytes
    assert offset > 0 and data.find(pixels[middle : middle + 8192], offset + 1) < 0
    start = offset - middle + 200_000
    data[start : start + 200_000] = np.random.default_rng(0).bytes(200_000)
    out = tmp_path_factory.mktemp("damaged") / "capture.bag"
    out.write_bytes(bytes(data))
    return out


def test_damaged_bag_is_refused(damaged_bag: Path) -> None:
    with pytest.raises(CaptureError, match=r"capture\.bag: 1 physically implausible depth frame"):
        load_capture(damaged_bag)
    with pytest.raises(CaptureError, match=r"frame 3: \d+% of neighbouring pixels jump.*=drop"):
        load_capture(damaged_bag)


def test_damaged_bag_with_drop_invalidates_that_frame(damaged_bag: Path, demo_dir: Path) -> None:
    with pytest.warns(CaptureWarning, match=r"frame 3:.*their depth was made invalid"):
        cap = load_capture(damaged_bag, IngestParams(implausible_depth="drop"))
    assert cap.implausible_depth == [3] and np.isnan(cap.depth[3]).all()
    good = load_capture(demo_dir / "capture.bag")
    others = [t for t in range(N_FRAMES) if t != 3]
    np.testing.assert_array_equal(cap.depth[others], good.depth[others])
    np.testing.assert_array_equal(cap.color, good.color)


def test_all_zero_depth_is_refused(demo_dir: Path, tmp_path: Path) -> None:
    import cv2

    rgbd = tmp_path / "rgbd"
    shutil.copytree(demo_dir / "rgbd", rgbd)
    for f in (rgbd / "depth").glob("*.png"):
        cv2.imwrite(str(f), np.zeros((480, 640), np.uint16))
    with pytest.raises(CaptureError, match=r"rgbd: no valid depth in any of the 6 frames"):
        load_capture(rgbd)
