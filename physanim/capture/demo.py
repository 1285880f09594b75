"""The embedded demo dataset: a virtual actor (real face000 scan) performing a known
expression sequence in front of a virtual RealSense-like RGB-D camera and a stereo pair.
``DemoParams.performance`` picks the sequence from ``physanim.capture.library`` (default: the
demo's jaw drop and asymmetric smile); ``DemoParams.markers`` paints the marker dots or not.

Layout of the dataset directory (written to a temporary sibling, renamed at the end, so a
crash never leaves a half dataset that looks complete)::

    capture.bag            RealSense ROS1 bag (colour rgb8 + registered depth z16)
    rgbd/color/000000.png  Open3D RGBD folder: colour PNG, depth uint16 PNG,
    rgbd/depth/000000.png  intrinsic.json (Open3D PinholeCameraIntrinsic + depth_scale, fps)
    rgbd/intrinsic.json
    stereo/left/000000.png rectified stereo pair (left = the colour camera)
    stereo/right/000000.png
    stereo/calibration.yaml OpenCV FileStorage: K1 D1 K2 D2 R T image_width image_height fps
    ground_truth.zarr      see ``write_ground_truth``
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import zarr

from physanim.capture.actor import build_actor
from physanim.capture.bag_writer import RealSenseBagWriter
from physanim.capture.camera_rig import CameraRig, realsense_like_rig, to_camera
from physanim.capture.library import performance_setup
from physanim.capture.markers import place_markers
from physanim.capture.params import DemoParams
from physanim.capture.performance import ExpressionModel
from physanim.capture.synth_render import (
    SkinTexture,
    color_to_uint8,
    depth_sensor,
    render_view,
)

#: Direction towards the key light in the colour camera frame (upper left, in front).
LIGHT_CAM = np.array([-0.35, -0.5, -0.8]) / np.linalg.norm([-0.35, -0.5, -0.8])


def write_rgbd_intrinsics(
    path: Path, K: np.ndarray, size: tuple[int, int], depth_scale: float, fps: float
) -> None:
    """Open3D ``intrinsic.json`` (column-major matrix) plus ``depth_scale`` (units/m), ``fps``."""
    h, w = size
    data = {
        "width": w,
        "height": h,
        "intrinsic_matrix": K.T.ravel().tolist(),
        "depth_scale": depth_scale,
        "fps": fps,
    }
    path.write_text(json.dumps(data, indent=2))


def write_stereo_calibration(path: Path, rig: CameraRig, fps: float) -> None:
    """OpenCV YAML: K1, D1, K2, D2, R (right <- left), T (m), image size, fps."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("K1", rig.K)
    fs.write("D1", np.zeros((1, 5)))
    fs.write("K2", rig.K)
    fs.write("D2", np.zeros((1, 5)))
    fs.write("R", np.eye(3))
    fs.write("T", np.array([[-rig.baseline], [0.0], [0.0]]))
    fs.write("image_width", rig.size[1])
    fs.write("image_height", rig.size[0])
    fs.write("fps", float(fps))
    fs.release()


def _write_png(image: np.ndarray, *paths: Path) -> None:
    """Encode an RGB (H, W, 3) or single-channel (H, W) image once and write it to ``paths``."""
    img = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    ok, png = cv2.imencode(".png", img)
    if not ok:
        raise OSError(f"{paths[0]}: cannot encode the image as PNG")
    for path in paths:
        path.write_bytes(png.tobytes())


def generate_demo(
    out_dir: Path,
    *,
    seed: int | None = None,
    n_frames: int | None = None,
    fps: float | None = None,
    params: DemoParams | None = None,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
) -> Path:
    """Generate the demo dataset into ``out_dir`` and return ``out_dir``: the recording and
    its truth replace those already there; other entries (``runs/``) stay.

    ``seed``, ``n_frames``, ``fps`` override the same fields of ``params`` (defaults:
    ``DemoParams()``: seed 0, 90 frames at 30 fps). Deterministic for given parameters, and
    the same for any number of ``workers`` (processes rendering frames; default one per core).
    """
    p = params or DemoParams()
    overrides = {"seed": seed, "n_frames": n_frames, "fps": fps}
    p = DemoParams(**{**p.model_dump(), **{k: v for k, v in overrides.items() if v is not None}})
    out_dir = Path(out_dir)
    tmp = out_dir.parent / f".{out_dir.name}.partial-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    (tmp / "rgbd" / "color").mkdir(parents=True)
    (tmp / "rgbd" / "depth").mkdir()
    (tmp / "stereo" / "left").mkdir(parents=True)
    (tmp / "stereo" / "right").mkdir()
    try:
        _generate_into(tmp, p, progress, workers or default_workers())
        _move_into(tmp, out_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out_dir


#: The recordings ``generate_demo`` writes, moved into place last (a dataset counts as
#: recorded once one is there), the bag, which ingest prefers, last of all.
_RECORDINGS = ("rgbd", "capture.bag")


def _move_into(tmp: Path, out_dir: Path) -> None:
    """Rename the entries of ``tmp`` into ``out_dir`` (made if missing), replacing same-named
    ones and leaving the rest (the run directory, whose Prefect server may be starting
    meanwhile)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    names = sorted(
        (e.name for e in tmp.iterdir()),
        key=lambda n: _RECORDINGS.index(n) if n in _RECORDINGS else -1,
    )
    old = out_dir.parent / f".{out_dir.name}.old-{os.getpid()}"
    shutil.rmtree(old, ignore_errors=True)
    old.mkdir()
    try:
        for name in names:
            if (out_dir / name).exists():
                (out_dir / name).rename(old / name)
            (tmp / name).rename(out_dir / name)
    finally:
        shutil.rmtree(old, ignore_errors=True)


@dataclass(frozen=True)
class _Scene:
    """What rendering one frame needs (sent once to each worker process)."""

    v0: np.ndarray
    faces: np.ndarray
    m0: np.ndarray
    field: ExpressionModel
    expression: np.ndarray
    head: np.ndarray
    rig: CameraRig
    texture: SkinTexture
    p: DemoParams


@dataclass(frozen=True)
class _Frame:
    """One rendered frame: uint8 ``color`` / ``color_right`` (H, W, 3), uint16 sensor
    ``depth`` (H, W), float32 ``vertices`` (N, 3) m (actor frame) and ``depth_true`` (H, W) m."""

    color: np.ndarray
    color_right: np.ndarray
    depth: np.ndarray
    vertices: np.ndarray
    depth_true: np.ndarray


def _render_frame(scene: _Scene, t: int) -> _Frame:
    """Frame ``t``: colour and depth of the colour camera, the right stereo image, truth.
    Depends on ``t`` only through its own seed, so frames can be rendered in any order."""
    p, rig = scene.p, scene.rig
    va = scene.v0 + scene.field.displacement(scene.v0, scene.expression[t])
    vw = va @ scene.head[t, :3, :3].T + scene.head[t, :3, 3]
    view_kw = dict(marker_radius=p.marker_radius_m, light_cam=LIGHT_CAM, supersample=p.supersample)
    dots = scene.m0 if p.markers else None
    args = (scene.v0, scene.faces, rig.K, rig.size, scene.texture, dots)
    left = render_view(to_camera(vw, rig.pose_left), *args, **view_kw)
    right = render_view(to_camera(vw, rig.pose_right), *args, with_depth=False, **view_kw)
    rng = np.random.default_rng([p.seed, t])
    color = color_to_uint8(left.color, rng, p.color_noise)
    color_r = color_to_uint8(right.color, rng, p.color_noise)
    depth = depth_sensor(
        left,
        rng,
        depth_unit_m=p.depth_unit_m,
        sigma_at_0_5m=p.depth_noise_m,
        min_cos_view=p.min_cos_view,
    )
    return _Frame(color, color_r, depth, va.astype(np.float32), left.depth.astype(np.float32))


_WORKER_SCENE: _Scene | None = None


def _init_worker(scene: _Scene) -> None:
    global _WORKER_SCENE
    _WORKER_SCENE = scene
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)  # one process per core; no BLAS threads on top


def _worker_frame(t: int) -> _Frame:
    assert _WORKER_SCENE is not None
    return _render_frame(_WORKER_SCENE, t)


def _rendered_frames(scene: _Scene, workers: int) -> Iterator[_Frame]:
    """Frames 0..T-1 in order, rendered by ``workers`` processes (1: in this process)."""
    n = scene.p.n_frames
    # the first frame renders here: that loads the compiled rasteriser, which forked
    # workers then inherit instead of each loading it again
    yield _render_frame(scene, 0)
    if workers <= 1 or n < 3:
        yield from (_render_frame(scene, t) for t in range(1, n))
        return
    # fork: the workers inherit the imported modules (a fresh interpreter would spend
    # seconds importing open3d); they only run numpy/scipy/numba on their own arrays
    ctx = multiprocessing.get_context("fork" if sys.platform == "linux" else "spawn")
    with ProcessPoolExecutor(workers, ctx, initializer=_init_worker, initargs=(scene,)) as pool:
        yield from pool.map(_worker_frame, range(1, n))


def default_workers() -> int:
    """Processes that render demo frames: one per core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _generate_into(
    root: Path, p: DemoParams, progress: Callable[[int, int], None] | None, workers: int
) -> None:
    actor = build_actor()
    v0, faces = actor.vertices, actor.faces
    markers = place_markers(v0, faces)
    m0 = markers.positions(v0, faces)
    field, perf = performance_setup(
        p.performance, dict(zip(markers.names, m0, strict=True)), p.n_frames, p.fps, p.seed
    )
    head = perf.head_pose()
    rig = realsense_like_rig(distance_m=p.camera_distance_m, baseline_m=p.stereo_baseline_m)
    scene = _Scene(v0, faces, m0, field, perf.params, head, rig, SkinTexture.random(p.seed), p)
    h, w = rig.size
    T, N, K = p.n_frames, len(v0), len(markers.names)

    gt = zarr.open_group(root / "ground_truth.zarr", mode="w")
    arrays = {
        "vertices_actor": ((T, N, 3), (1, N, 3)),
        "markers_actor": ((T, K, 3), (T, K, 3)),
        "markers_camera": ((T, K, 3), (T, K, 3)),
        "depth_true": ((T, h, w), (1, h, w)),
    }
    gt_arr = {
        name: gt.create_array(name, shape=shape, chunks=chunks, dtype="float32", fill_value=np.nan)
        for name, (shape, chunks) in arrays.items()
    }
    with RealSenseBagWriter(
        root / "capture.bag", rig.K, rig.size, fps=p.fps, depth_scale=p.depth_unit_m
    ) as bag:
        for t, frame in enumerate(_rendered_frames(scene, workers)):
            name = f"{t:06d}.png"
            # the stereo pair's left camera is the colour camera: the same image in both
            _write_png(frame.color, root / "rgbd" / "color" / name, root / "stereo" / "left" / name)
            _write_png(frame.depth, root / "rgbd" / "depth" / name)
            _write_png(frame.color_right, root / "stereo" / "right" / name)
            bag.add_frame(frame.color, frame.depth, perf.times[t])
            gt_arr["vertices_actor"][t] = frame.vertices
            gt_arr["depth_true"][t] = frame.depth_true
            if progress is not None:
                progress(t + 1, T)

    verts = gt_arr["vertices_actor"][:]
    m_actor = markers.positions(verts.astype(np.float64), faces)
    m_world = np.einsum("tij,tkj->tki", head[:, :3, :3], m_actor) + head[:, None, :3, 3]
    gt_arr["markers_actor"][:] = m_actor.astype(np.float32)
    gt_arr["markers_camera"][:] = to_camera(m_world, rig.pose_left).astype(np.float32)
    for name, value in {
        "neutral_vertices": v0,
        "faces": faces,
        "marker_face": markers.face,
        "marker_bary": markers.bary,
        "markers_neutral": m0,
        "expression": perf.params,
        "head_pose": head,
        "timestamps": perf.times,
        "K": rig.K,
        "camera_pose": rig.pose_left,
        "right_camera_pose": rig.pose_right,
    }.items():
        gt.create_array(name, data=np.asarray(value))
    gt.attrs.update(
        {
            "marker_names": list(markers.names),
            "expression_names": list(field.param_names),
            "expression_model": type(field).__name__,
            "performance": p.performance,
            "expression_field": field.to_dict(),
            "head_center": perf.head_center.tolist(),
            "image_size": [h, w],
            "stereo_baseline_m": rig.baseline,
            "fps": p.fps,
            "depth_unit_m": p.depth_unit_m,
            "demo_params": p.model_dump(),
            "frames": (
                "vertices_actor/markers_actor: head-fixed actor frame (m); head_pose (T,4,4) "
                "world <- actor; camera_pose/right_camera_pose (4,4) world <- camera (OpenCV "
                "axes); markers_camera and depth_true (z, NaN off the face): colour camera"
            ),
        }
    )
    write_rgbd_intrinsics(
        root / "rgbd" / "intrinsic.json", rig.K, rig.size, 1.0 / p.depth_unit_m, p.fps
    )
    write_stereo_calibration(root / "stereo" / "calibration.yaml", rig, p.fps)
