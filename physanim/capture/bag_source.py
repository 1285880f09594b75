"""Read a RealSense ``.bag`` through Open3D's ``RSBagReader`` (no pyrealsense2).

Open3D replays the bag in real time through librealsense, aligns depth to colour and
returns frames without their capture timestamps (``get_timestamp`` is the playback
position, measured jittering by +-1 frame period); it may drop the first frames or return
a frame twice. So the bag's own colour messages are indexed with ``rosbags`` (header
stamps, raw bytes): each frame from Open3D is identified by the hash of its colour bytes,
which gives its exact timestamp, removes duplicates and reveals drops. Frames Open3D
dropped can be recovered from the raw messages when depth is already registered to colour
(same intrinsics and size, which the index checks).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Reader
from rosbags.typesys import Stores, get_typestore

from physanim.capture.frames import Capture, CaptureError, check_gaps, depth_to_metres
from physanim.capture.params import IngestParams

COLOR_ENCODINGS = {"rgb8": (3, False), "bgr8": (3, True), "rgba8": (4, False), "bgra8": (4, True)}


@dataclass
class _BagIndex:
    stamps: np.ndarray  # (F,) s, colour messages in file order
    hashes: list[bytes]
    color_raw: list[tuple[bytes, str, int, int]]
    depth_raw: dict[float, bytes]
    registered: bool


def _digest(data: bytes | np.ndarray) -> bytes:
    return hashlib.blake2b(
        memoryview(np.ascontiguousarray(data)).cast("B"), digest_size=16
    ).digest()


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def _index_bag(path: Path) -> _BagIndex:
    ts = get_typestore(Stores.ROS1_NOETIC)
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags raises several types for corrupt files
        raise CaptureError(
            f"{path}: unreadable or truncated RealSense bag ({type(exc).__name__}: {exc}); "
            "re-copy or re-record it"
        ) from exc
    try:
        conns = [c for c in reader.connections if c.topic.endswith("/image/data")]
        infos = {c.topic: c for c in reader.connections if c.topic.endswith("/info/camera_info")}
        color = [c for c in conns if "/Color_" in c.topic]
        depth = [c for c in conns if "/Depth_" in c.topic]
        if not color or not depth:
            raise CaptureError(
                f"{path}: the bag has no {'colour' if not color else 'depth'} image stream "
                "(expected RealSense topics /device_0/sensor_*/Color_0|Depth_0/image/data)"
            )
        cams = {}
        for topic, conn in infos.items():
            for _, _, raw in reader.messages(connections=[conn]):
                msg = ts.deserialize_ros1(raw, conn.msgtype)
                cams[topic.split("/info/")[0]] = (tuple(msg.K), msg.width, msg.height)
        prefixes = [c.topic.split("/image/")[0] for c in (color[0], depth[0])]
        registered = len(cams) >= 2 and cams.get(prefixes[0]) == cams.get(prefixes[1])
        stamps, hashes, color_raw, depth_raw = [], [], [], {}
        for conn, _, raw in reader.messages(connections=[color[0], depth[0]]):
            msg = ts.deserialize_ros1(raw, conn.msgtype)
            if conn is color[0]:
                stamps.append(_stamp(msg))
                hashes.append(_digest(msg.data))
                color_raw.append((bytes(msg.data), msg.encoding, msg.height, msg.width))
            else:
                depth_raw[_stamp(msg)] = bytes(msg.data)
    except CaptureError:
        raise
    except Exception as exc:
        raise CaptureError(
            f"{path}: unreadable or truncated RealSense bag ({type(exc).__name__}: {exc}); "
            "re-copy or re-record it"
        ) from exc
    finally:
        reader.close()
    return _BagIndex(np.asarray(stamps), hashes, color_raw, depth_raw, registered)


def _color_from_raw(data: bytes, encoding: str, h: int, w: int, path: Path) -> np.ndarray:
    if encoding not in COLOR_ENCODINGS:
        raise CaptureError(
            f"{path}: unsupported colour pixel format {encoding!r}; supported: "
            f"{sorted(COLOR_ENCODINGS)}"
        )
    channels, bgr = COLOR_ENCODINGS[encoding]
    img = np.frombuffer(data, np.uint8).reshape(h, w, channels)[..., :3]
    return img[..., ::-1] if bgr else img


def read_bag(
    path: Path, params: IngestParams, progress: Callable[[int, int], None] | None = None
) -> Capture:
    """Ingest a RealSense bag; see the module docstring for how frames are identified."""
    import open3d as o3d

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: bag file not found")
    index = _index_bag(path)
    if len(index.stamps) == 0:
        raise CaptureError(f"{path}: the bag contains no colour frames")
    if np.any(np.diff(index.stamps) < 0):
        bad = int(np.argmax(np.diff(index.stamps) < 0)) + 1
        raise CaptureError(
            f"{path}: colour frames out of order (message {bad} has an earlier timestamp than "
            "the one before); re-export the bag in capture order"
        )
    reader = o3d.t.io.RSBagReader()
    if not reader.open(str(path)):
        raise CaptureError(f"{path}: Open3D RSBagReader cannot open the bag (not a RealSense bag?)")
    try:
        md = reader.metadata
        if md.color_format not in ("RGB8", "BGR8", "RGBA8", "BGRA8"):
            raise CaptureError(
                f"{path}: unsupported colour pixel format {md.color_format!r}; supported: "
                "RGB8, BGR8, RGBA8, BGRA8"
            )
        depth_scale = float(f"{1.0 / md.depth_scale:.6g}")  # Open3D gives units per metre
        fps = float(md.fps)
        K = np.asarray(md.intrinsics.intrinsic_matrix, dtype=np.float64)
        h, w = md.height, md.width
        stamp0 = index.stamps[0]
        grid = np.rint((index.stamps - stamp0) * fps).astype(np.int64)
        by_hash: dict[bytes, list[int]] = {}
        for i, hsh in enumerate(index.hashes):
            by_hash.setdefault(hsh, []).append(i)
        frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        duplicated: list[int] = []
        n_total = len(index.stamps)
        while not reader.is_eof():
            rgbd = reader.next_frame()
            if rgbd.is_empty():
                break
            color = np.asarray(rgbd.color)
            depth = np.asarray(rgbd.depth).reshape(h, w)
            cands = [i for i in by_hash.get(_digest(color), []) if grid[i] not in frames]
            if not cands:
                known = by_hash.get(_digest(color))
                if known:
                    duplicated.append(int(grid[known[0]]))
                    continue
                raise CaptureError(f"{path}: Open3D returned a frame not found in the bag")
            rgb = color[..., :3][..., ::-1] if md.color_format.startswith("BGR") else color[..., :3]
            frames[int(grid[cands[0]])] = (np.ascontiguousarray(rgb), depth.copy())
            if progress is not None:
                progress(len(frames), n_total)
    finally:
        reader.close()

    recovered = []
    if params.fill_dropped_bag_frames and index.registered:
        for i, g in enumerate(grid.tolist()):
            raw_depth = index.depth_raw.get(index.stamps[i])
            if g in frames or raw_depth is None:
                continue
            data, enc, hh, ww = index.color_raw[i]
            color = _color_from_raw(data, enc, hh, ww, path)
            frames[g] = (color, np.frombuffer(raw_depth, np.uint16).reshape(hh, ww).copy())
            recovered.append(g)
    order = np.array(sorted(frames), dtype=np.int64)
    dropped = check_gaps(order, str(path), params.max_missing_fraction)
    dropped = sorted(set(dropped) | (set(grid.tolist()) - set(frames)))
    stamp_of = {int(g): index.stamps[i] - stamp0 for i, g in enumerate(grid)}
    return Capture(
        color=np.stack([frames[g][0] for g in order]),
        depth=depth_to_metres(np.stack([frames[g][1] for g in order]), depth_scale),
        K=K,
        depth_scale=depth_scale,
        timestamps=np.array([stamp_of[g] for g in order.tolist()]),
        frame_index=order,
        fps=fps,
        source=f"RealSense bag {path.name} via Open3D RSBagReader ({h}x{w} @ {fps:g} fps)",
        dropped=dropped,
        duplicated=sorted(set(duplicated)),
        recovered=sorted(recovered),
    )
