"""Write RGB-D frames as a RealSense ROS1 bag (file format version 3) with ``rosbags``.

Topics follow librealsense's ``src/media/ros/ros_file_format.h`` so that Open3D's
``o3d.t.io.RSBagReader`` (librealsense playback) can replay the file: device and sensor
info (KeyValue), per-stream ``info`` (realsense_msgs/StreamInfo), ``info/camera_info``,
``tf/0`` extrinsics, ``image/data`` + ``image/metadata`` per frame, and the depth
sensor's ``option/Depth Units/value``. Depth is registered to colour (identity
extrinsics, same intrinsics), so aligning depth to colour is a no-op.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

STREAM_INFO_MSG = "uint32 fps\nstring encoding\nbool is_recommended\n"
DEPTH_PREFIX = "/device_0/sensor_0/Depth_0"
#: rosbag rejects time 0 (ros::TIME_MIN is 1 ns): every message time is offset by this.
T0_NS = 1
COLOR_PREFIX = "/device_0/sensor_1/Color_0"


def _typestore():
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(STREAM_INFO_MSG, "realsense_msgs/msg/StreamInfo"))
    return store


class RealSenseBagWriter:
    """Incremental writer: ``add_frame`` per frame, then ``close`` (or use as a context manager).

    ``K`` (3, 3) pixel intrinsics shared by colour and depth; ``size`` = (H, W);
    ``depth_scale`` metres per depth unit; ``fps`` frames per second.
    """

    def __init__(
        self,
        path: Path,
        K: np.ndarray,
        size: tuple[int, int],
        *,
        fps: float,
        depth_scale: float = 0.001,
        serial: str = "000000000001",
    ) -> None:
        self.ts = _typestore()
        self.height, self.width = size
        self.fps = fps
        self.writer = Writer(Path(path))
        self.writer.open()
        self._conns: dict[str, object] = {}
        self._seq = 0
        self._write_static(np.asarray(K, dtype=np.float64), depth_scale, serial)

    def _conn(self, topic: str, msgtype: str):
        if topic not in self._conns:
            self._conns[topic] = self.writer.add_connection(
                topic, msgtype, typestore=self.ts, latching=1
            )
        return self._conns[topic]

    def _write(self, topic: str, msgtype: str, msg, t_ns: int) -> None:
        self.writer.write(self._conn(topic, msgtype), t_ns, self.ts.serialize_ros1(msg, msgtype))

    def _keyvalues(self, topic: str, items: dict[str, str], t_ns: int = T0_NS) -> None:
        kv = self.ts.types["diagnostic_msgs/msg/KeyValue"]
        for key, value in items.items():
            self._write(topic, kv.__msgtype__, kv(key=key, value=value), t_ns)

    def _header(self, t_s: float, seq: int):
        t = self.ts.types
        sec = int(t_s)
        stamp = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t_s - sec) * 1e9)))
        return t["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id="0")

    def _write_static(self, K: np.ndarray, depth_scale: float, serial: str) -> None:
        t = self.ts.types
        u32 = t["std_msgs/msg/UInt32"]
        self._write("/file_version", u32.__msgtype__, u32(data=3), T0_NS)
        self._keyvalues(
            "/device_0/info",
            {
                "Name": "Intel RealSense D435 (physanim virtual)",
                "Serial Number": serial,
                "Firmware Version": "5.13.0.50",
                "Product Id": "0B07",
                "Physical Port": "virtual",
                "Product Line": "D400",
            },
        )
        self._keyvalues("/device_0/sensor_0/info", {"Name": "Stereo Module"})
        self._keyvalues("/device_0/sensor_1/info", {"Name": "RGB Camera"})
        f32, text = t["std_msgs/msg/Float32"], t["std_msgs/msg/String"]
        opt = "/device_0/sensor_0/option/Depth Units"
        self._write(f"{opt}/value", f32.__msgtype__, f32(data=float(depth_scale)), T0_NS)
        desc = text(data="Number of meters represented by a single depth unit")
        self._write(f"{opt}/description", text.__msgtype__, desc, T0_NS)
        info_t = t["realsense_msgs/msg/StreamInfo"]
        cam_t = t["sensor_msgs/msg/CameraInfo"]
        tf_t = t["geometry_msgs/msg/Transform"]
        roi = t["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        P = np.zeros(12)
        P[[0, 2, 5, 6, 10]] = [K[0, 0], K[0, 2], K[1, 1], K[1, 2], 1.0]
        for prefix, encoding in ((DEPTH_PREFIX, "mono16"), (COLOR_PREFIX, "rgb8")):
            self._write(
                f"{prefix}/info",
                info_t.__msgtype__,
                info_t(fps=int(round(self.fps)), encoding=encoding, is_recommended=True),
                T0_NS,
            )
            cam = cam_t(
                header=self._header(0.0, 0),
                height=self.height,
                width=self.width,
                distortion_model="Brown Conrady",
                D=np.zeros(5),
                K=K.ravel().copy(),
                R=np.eye(3).ravel(),
                P=P,
                binning_x=0,
                binning_y=0,
                roi=roi,
            )
            self._write(f"{prefix}/info/camera_info", cam_t.__msgtype__, cam, T0_NS)
            tf = tf_t(
                translation=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            )
            self._write(f"{prefix}/tf/0", tf_t.__msgtype__, tf, T0_NS)

    def add_frame(self, color: np.ndarray, depth: np.ndarray, t_s: float) -> None:
        """Append a frame: ``color`` (H, W, 3) uint8 RGB, ``depth`` (H, W) uint16, time t_s s."""
        if color.shape != (self.height, self.width, 3) or color.dtype != np.uint8:
            raise ValueError(f"color: expected ({self.height}, {self.width}, 3) uint8")
        if depth.shape != (self.height, self.width) or depth.dtype != np.uint16:
            raise ValueError(f"depth: expected ({self.height}, {self.width}) uint16")
        self._seq += 1
        img_t = self.ts.types["sensor_msgs/msg/Image"]
        t_ns = int(round(t_s * 1e9)) + T0_NS
        for prefix, data, enc, step in (
            (DEPTH_PREFIX, depth, "mono16", 2 * self.width),
            (COLOR_PREFIX, color, "rgb8", 3 * self.width),
        ):
            msg = img_t(
                header=self._header(t_s, self._seq),
                height=self.height,
                width=self.width,
                encoding=enc,
                is_bigendian=0,
                step=step,
                data=np.ascontiguousarray(data).view(np.uint8).ravel(),
            )
            self._write(f"{prefix}/image/data", img_t.__msgtype__, msg, t_ns)
            self._keyvalues(
                f"{prefix}/image/metadata",
                {
                    "timestamp_domain": "System Time",
                    "system_time": f"{t_s * 1e3:.6f}",
                    "Frame Timestamp": f"{int(round(t_s * 1e6))}",
                },
                t_ns,
            )

    def close(self) -> None:
        self.writer.close()

    def __enter__(self) -> RealSenseBagWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_bag(
    path: Path,
    colors: np.ndarray,
    depths: np.ndarray,
    K: np.ndarray,
    *,
    fps: float,
    depth_scale: float = 0.001,
    progress: Callable[[int, int], None] | None = None,
) -> None:
    """Write ``colors`` (T, H, W, 3) uint8 and ``depths`` (T, H, W) uint16 at ``fps`` to a bag."""
    with RealSenseBagWriter(path, K, depths.shape[1:], fps=fps, depth_scale=depth_scale) as w:
        for i in range(len(colors)):
            w.add_frame(colors[i], depths[i], i / fps)
            if progress is not None:
                progress(i + 1, len(colors))
