"""The demo dataset: layout, ground truth consistency, markers, expression field."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import zarr
from scipy.spatial.transform import Rotation

from physanim.capture.camera_rig import realsense_like_rig
from physanim.capture.markers import MARKER_XY_MM
from physanim.capture.performance import AnalyticFaceField, demo_performance
from physanim.capture.raster import project, rasterize
from physanim.capture.synth_render import SkinTexture
from physanim.face.landmarks import FEATURE_POINTS

from .conftest import N_FRAMES


def test_layout_is_complete_and_atomic(demo_dir: Path) -> None:
    for rel in ("capture.bag", "rgbd/intrinsic.json", "stereo/calibration.yaml"):
        assert (demo_dir / rel).is_file(), rel
    for sub in ("rgbd/color", "rgbd/depth", "stereo/left", "stereo/right"):
        assert len(list((demo_dir / sub).glob("*.png"))) == N_FRAMES, sub
    assert not [p for p in demo_dir.parent.iterdir() if p.name.startswith(".")]
    intr = json.loads((demo_dir / "rgbd/intrinsic.json").read_text())
    assert intr["width"] == 640 and intr["height"] == 480 and intr["depth_scale"] == 1000.0


def test_markers_cover_feature_points_and_project_on_the_face(ground_truth: zarr.Group) -> None:
    names = ground_truth.attrs["marker_names"]
    assert len(names) >= 30 and len(set(names)) == len(names)
    assert set(FEATURE_POINTS) <= set(names) and set(names) == set(MARKER_XY_MM)
    K = ground_truth["K"][:]
    depth = ground_truth["depth_true"][:]
    pts = ground_truth["markers_camera"][:].astype(np.float64)
    for t in range(N_FRAMES):
        uv = project(pts[t], K)
        col, row = np.rint(uv).astype(int).T
        assert ((col >= 0) & (col < 640) & (row >= 0) & (row < 480)).all()
        z_img = depth[t, row, col]
        # On the visible face: the rendered surface at the marker's pixel is the marker itself.
        assert np.isfinite(z_img).all()
        assert np.median(np.abs(z_img - pts[t, :, 2])) < 1e-3


def test_ground_truth_frames_are_consistent(ground_truth: zarr.Group) -> None:
    v = ground_truth["vertices_actor"][:].astype(np.float64)
    faces = ground_truth["faces"][:]
    neutral = ground_truth["neutral_vertices"][:]
    expr = ground_truth["expression"][:]
    assert v.shape == (N_FRAMES, len(neutral), 3) and expr.shape == (N_FRAMES, 3)
    # Sequence starts and ends neutral; the jaw opens in between.
    assert np.abs(expr[[0, -1]]).max() < 1e-6
    assert np.abs(v[0] - neutral).max() < 1e-6 and np.abs(v[-1] - neutral).max() < 1e-6
    assert expr[:, 0].max() > 0.5
    # Re-render frame 2's depth from the stored mesh, head pose and camera pose.
    head, cam = ground_truth["head_pose"][2], ground_truth["camera_pose"][:]
    world = v[2] @ head[:3, :3].T + head[:3, 3]
    cam_pts = (world - cam[:3, 3]) @ cam[:3, :3]
    ras = rasterize(cam_pts, faces, ground_truth["K"][:], (480, 640))
    stored = ground_truth["depth_true"][2]
    both = np.isfinite(stored) & np.isfinite(ras.depth)
    assert both.sum() > 5000 and np.abs(stored[both] - ras.depth[both]).max() < 1e-6


def test_jaw_field_is_a_rotation_below_the_lips_and_zero_above() -> None:
    field = AnalyticFaceField(ch_left=(0.02, -0.02, -0.01), ch_right=(-0.02, -0.02, -0.01))
    chin = np.array([[0.0, -0.045, -0.02]])
    forehead = np.array([[0.0, 0.05, -0.02]])
    d = field.displacement(np.vstack([chin, forehead]), np.array([1.0, 0.0, 0.0]))
    pivot = np.array(field.jaw_pivot)
    rot = Rotation.from_rotvec([field.jaw_max_angle, 0, 0]).as_matrix()
    np.testing.assert_allclose(d[0], (chin[0] - pivot) @ rot.T + pivot - chin[0], atol=1e-12)
    assert d[0, 1] < -0.005  # the chin drops by more than 5 mm
    np.testing.assert_allclose(d[1], 0.0, atol=1e-12)
    # Smile: the left corner moves by the smile vector; the right one 40 mm away by the
    # Gaussian tail exp(-d^2 / (2 sigma^2)) of it.
    corners = np.array([field.ch_left, field.ch_right])
    d = field.displacement(corners, np.array([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(d[0], field.smile_vector, atol=1e-12)
    tail = np.exp(-(0.04**2) / (2 * field.smile_sigma**2))
    np.testing.assert_allclose(d[1], tail * np.array(field.smile_vector), atol=1e-12)


def test_generators_are_deterministic_in_the_seed() -> None:
    a, b, c = (
        demo_performance(30, 30.0, 1),
        demo_performance(30, 30.0, 1),
        demo_performance(30, 30.0, 2),
    )
    np.testing.assert_array_equal(a.rotvec, b.rotvec)
    assert not np.allclose(a.rotvec, c.rotvec)
    np.testing.assert_array_equal(SkinTexture.random(3).freq, SkinTexture.random(3).freq)


def test_rig_intrinsics_are_realsense_like() -> None:
    rig = realsense_like_rig()
    assert rig.size == (480, 640) and 600 < rig.K[0, 0] < 630
    np.testing.assert_allclose(rig.pose_right[:3, 3] - rig.pose_left[:3, 3], [0.06, 0, 0])


def test_frames_rendered_in_parallel_match_serial(tmp_path: Path) -> None:
    from physanim.capture.demo import generate_demo

    serial = generate_demo(tmp_path / "serial", n_frames=3, workers=1)
    parallel = generate_demo(tmp_path / "parallel", n_frames=3, workers=2)
    images = sorted(p.relative_to(serial) for p in serial.rglob("*.png"))
    assert len(images) == 4 * 3
    for rel in images:
        assert (serial / rel).read_bytes() == (parallel / rel).read_bytes(), rel
    a = zarr.open_group(serial / "ground_truth.zarr", mode="r")
    b = zarr.open_group(parallel / "ground_truth.zarr", mode="r")
    for name in ("vertices_actor", "depth_true"):
        np.testing.assert_array_equal(a[name][:], b[name][:], err_msg=name)


def test_regenerating_replaces_the_recording_and_keeps_the_run_directory(tmp_path: Path) -> None:
    from physanim.capture.demo import generate_demo

    out = tmp_path / "demo"
    (out / "runs" / "prefect").mkdir(parents=True)
    (out / "runs" / "prefect" / "prefect.db").write_bytes(b"history")
    (out / "capture.bag").write_bytes(b"an older recording")
    generate_demo(out, n_frames=2, workers=1)
    assert (out / "runs" / "prefect" / "prefect.db").read_bytes() == b"history"
    assert (out / "capture.bag").stat().st_size > 1000
    frames = zarr.open_group(out / "ground_truth.zarr", mode="r")["vertices_actor"]
    assert frames.shape[0] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]  # no partial or old left
