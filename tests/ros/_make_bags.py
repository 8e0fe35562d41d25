"""Bags made directly with rosbags' writers (not weather-gym's): the "recorded by someone else" inputs
of the ROS tests. Small frames, few messages."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import cv2
import numpy as np
from rosbags import rosbag1, rosbag2
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

NOTE = "my_msgs/msg/Note"
NOTE_MSG = "string text\nint32 n\n"
T0 = 1_700_000_000_000_000_000  # a wall-clock start, as a real recording has
DT = 50_000_000  # 20 Hz


def frame(i: int, w: int, h: int) -> np.ndarray:
    """A textured RGB test frame, different for each i."""
    rng = np.random.default_rng(i)
    img = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    cv2.rectangle(img, (w // 4, h // 4), (w // 2, h // 2), (255, 120, 0), -1)
    return img


def qos(depth: int = 10, durability: QosDurability = QosDurability.VOLATILE) -> Qos:
    z = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE, durability, z, z, QosLiveliness.AUTOMATIC, z,
               False)


def _header(ts, ns: int, frame_id: str, ros1: bool = False):
    t = ts.types
    stamp = t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return t["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), stamp=stamp, frame_id=frame_id)


def camera_info(ts, ns: int, w: int, h: int, fx: float, ros1: bool = False):
    t = ts.types
    roi = t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    k = np.array([fx, 0, w / 2 + 1.5, 0, fx, h / 2 - 0.5, 0, 0, 1], np.float64)
    p = np.array([fx, 0, w / 2 + 1.5, 0, 0, fx, h / 2 - 0.5, 0, 0, 0, 1, 0], np.float64)
    names = ("D", "K", "R", "P") if ros1 else ("d", "k", "r", "p")
    return t["sensor_msgs/msg/CameraInfo"](header=_header(ts, ns, "cam", ros1), height=h, width=w,
                                           distortion_model="plumb_bob", **dict(zip(names, (np.zeros(5), k, np.eye(3).reshape(-1), p))),
                                           binning_x=0, binning_y=0, roi=roi)


def odometry(ts, ns: int, speed: float, yaw_rate: float):
    t = ts.types
    v3, q = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"]
    pose = t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                       orientation=q(x=0.0, y=0.0, z=0.0, w=1.0))
    return t["nav_msgs/msg/Odometry"](
        header=_header(ts, ns, "odom"), child_frame_id="base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](linear=v3(x=speed, y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=yaw_rate)),
            covariance=np.zeros(36)))


def image_msg(ts, rgb: np.ndarray, ns: int, encoding: str = "rgb8", pad: int = 0, ros1: bool = False):
    """A sensor_msgs/Image of ``rgb`` in ``encoding`` with ``pad`` bytes of row padding."""
    h, w = rgb.shape[:2]
    if encoding == "mono8":
        px = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)[..., None]
    elif encoding == "bgr8":
        px = rgb[..., ::-1]
    else:
        px = rgb
    rows = px.reshape(h, -1)
    if pad:
        rows = np.concatenate([rows, np.full((h, pad), 7, np.uint8)], axis=1)
    return ts.types["sensor_msgs/msg/Image"](header=_header(ts, ns, "cam", ros1), height=h, width=w, encoding=encoding,
                                             is_bigendian=0, step=rows.shape[1], data=np.ascontiguousarray(rows).reshape(-1))


def compressed_msg(ts, rgb: np.ndarray, ns: int, fmt: str = "jpeg"):
    ok, buf = cv2.imencode(".png" if fmt == "png" else ".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return ts.types["sensor_msgs/msg/CompressedImage"](header=_header(ts, ns, "cam"), format=fmt, data=buf.reshape(-1))


def ros2_bag(path: Path, *, storage: str = "mcap", n: int = 6, w: int = 96, h: int = 64, compressed: bool = True,
             encoding: str = "rgb8", pad: int = 0, odom: bool = True, note: bool = True, fx: float = 80.0) -> Path:
    """A rosbag2 bag: /cam/image_raw[/compressed] (n frames), /cam/camera_info, /odom (twice per frame),
    /note (a custom type with its definition), each with its own QoS."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(NOTE_MSG, NOTE))
    plugin = rosbag2.StoragePlugin.MCAP if storage == "mcap" else rosbag2.StoragePlugin.SQLITE3
    with rosbag2.Writer(path, version=9, storage_plugin=plugin) as wr:
        img_t = "sensor_msgs/msg/CompressedImage" if compressed else "sensor_msgs/msg/Image"
        cam = wr.add_connection("/cam/image_raw/compressed" if compressed else "/cam/image_raw", img_t, typestore=ts,
                                offered_qos_profiles=[qos(5)])
        info = wr.add_connection("/cam/camera_info", "sensor_msgs/msg/CameraInfo", typestore=ts,
                                 offered_qos_profiles=[qos(1, QosDurability.TRANSIENT_LOCAL)])
        od = wr.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts) if odom else None
        nt = wr.add_connection("/note", NOTE, typestore=ts) if note else None
        for i in range(n):
            ns = T0 + i * DT
            wr.write(info, ns, ts.serialize_cdr(camera_info(ts, ns, w, h, fx), "sensor_msgs/msg/CameraInfo"))
            if od is not None:
                for j in (0, 1):
                    m = odometry(ts, ns + j * 10, 8.0 + i, 0.5 - 0.2 * i)
                    wr.write(od, ns + j * 10, ts.serialize_cdr(m, "nav_msgs/msg/Odometry"))
            msg = compressed_msg(ts, frame(i, w, h), ns + 20) if compressed else image_msg(
                ts, frame(i, w, h), ns + 20, encoding, pad)
            wr.write(cam, ns + 20, ts.serialize_cdr(msg, img_t))
            if nt is not None:
                wr.write(nt, ns + 30, ts.serialize_cdr(ts.types[NOTE](text=f"note {i}", n=i), NOTE))
    return path


def ros1_bag(path: Path, *, n: int = 4, w: int = 80, h: int = 48, encoding: str = "bgr8") -> Path:
    ts = get_typestore(Stores.ROS1_NOETIC)
    with rosbag1.Writer(path) as wr:
        cam = wr.add_connection("/camera/image_raw", "sensor_msgs/msg/Image", typestore=ts, callerid="/zed", latching=0)
        info = wr.add_connection("/camera/camera_info", "sensor_msgs/msg/CameraInfo", typestore=ts)
        for i in range(n):
            ns = T0 + i * DT
            wr.write(info, ns, ts.serialize_ros1(camera_info(ts, ns, w, h, 60.0, ros1=True), "sensor_msgs/msg/CameraInfo"))
            wr.write(cam, ns + 5, ts.serialize_ros1(image_msg(ts, frame(i, w, h), ns + 5, encoding, ros1=True),
                                                    "sensor_msgs/msg/Image"))
    return path


def strip_definition(bag: Path, msgtype: str = NOTE) -> None:
    """Remove ``msgtype``'s definition from a SQLite rosbag2 bag (as old recorders left them)."""
    db = sqlite3.connect(next(bag.glob("*.db3")))
    with db:
        db.execute("DELETE FROM message_definitions WHERE topic_type = ?", (msgtype,))
        db.execute("UPDATE topics SET type_description_hash = '' WHERE type = ?", (msgtype,))
    db.close()
