"""An episode as an MCAP rosbag2 (``weather-gym lap --bag OUT``): what the car saw and did, for Foxglove,
RViz or ``ros2 bag play``, written without ROS (message definitions embedded as text).

Topics (sim time from 0; frames ``map``, ``odom``, ``base_footprint``, ``camera_link``
(x forward) and ``camera_optical`` (z forward: the images' frame)):

====================================  ============================================  ==============================
topic                                 type                                          what
====================================  ============================================  ==============================
``/camera/image_raw[/compressed]``    ``sensor_msgs/Image`` (rgb8) or               the camera frame, clear
                                      ``CompressedImage`` (JPEG)
``/camera/image_weathered[...]``      the same                                      the frame the perception saw
                                                                                    (with weather only)
``/camera/camera_info``               ``sensor_msgs/CameraInfo``                    pinhole K, P (no distortion)
``/perception/cones``                 ``eufs_msgs/ConeArrayWithCovariance``         detected cones, car frame
``/ground_truth/cones``               ``eufs_msgs/ConeArrayWithCovariance``         the track's cones, map frame
                                                                                    (once, latched)
``/odom``                             ``nav_msgs/Odometry``                         the car's odometry (drifts)
``/ground_truth/odom``                ``nav_msgs/Odometry``                         the true pose and speed
``/tf``, ``/tf_static``               ``tf2_msgs/TFMessage``                        map -> base_footprint (true),
                                                                                    base_footprint -> camera_link
                                                                                    -> camera_optical
====================================  ============================================  ==============================

A cone's covariance is the range/bearing noise model :class:`ConeNoise` (``weather-gym lap`` passes the
mapper's: range std ``range_std + range_std_rel * range``, across-sight std ``range * bearing_std``)
turned into x-y in the car frame, row major in ``float64[4]``.

Example:
    >>> import tempfile, numpy as np
    >>> from weather_gym.camera.config import CameraConfig
    >>> cam = CameraConfig(width=64, height=36)
    >>> out = tempfile.mkdtemp() + "/lap"
    >>> with EpisodeBag(out, camera=cam, cones_xy=np.zeros((1, 2)), cone_classes=np.zeros(1, int)) as bag:
    ...     bag.add(0.0, clear=np.zeros((36, 64, 3), np.uint8), pose=(0, 0, 0), speed=0.0, yaw_rate=0.0)
    >>> sorted(bag.counts)[:3]
    ['/camera/camera_info', '/camera/image_raw/compressed', '/ground_truth/cones']
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError, OutputPathError
from weather_gym.perception.cones import FIELD
from weather_gym.ros._deps import latched_qos, lib
from weather_gym.ros.bag_output import bag_output, check_bag_output
from weather_gym.ros.messages import CONE_ARRAY, CONE_FIELDS, header, rgb_to_image, typestore

__all__ = ["BAG_IMAGES", "ConeNoise", "EpisodeBag"]

BAG_IMAGES = ("jpeg", "raw")
"""How the camera frames are stored: ``jpeg`` (``CompressedImage``, quality :data:`JPEG_QUALITY`: about a
tenth of the size) or ``raw`` (``Image`` rgb8, the exact pixels)."""
JPEG_QUALITY = 90
OPTICAL = (-0.5, 0.5, -0.5, 0.5)
"""camera_link (x forward, z up) -> camera_optical (z forward, x right, y down), REP 103."""


@dataclass(frozen=True)
class ConeNoise:
    """Range/bearing noise of a cone measurement: std along the line of sight ``range_std +
    range_std_rel * range`` (m), across it ``max(range, 0.1) * bearing_std`` (rad -> m)."""

    range_std: float = 0.05
    range_std_rel: float = 0.04
    bearing_std: float = 0.01

    def covariance(self, ranges: np.ndarray, bearings: np.ndarray) -> np.ndarray:
        """(N, 4) x-y covariances, row major, for cones at ``ranges`` (m) and ``bearings`` (rad)."""
        r = np.asarray(ranges, np.float64)
        sr = self.range_std + self.range_std_rel * r
        sb = np.maximum(r, 0.1) * self.bearing_std
        c, s = np.cos(bearings), np.sin(bearings)
        xx = c * c * sr**2 + s * s * sb**2
        yy = s * s * sr**2 + c * c * sb**2
        xy = c * s * (sr**2 - sb**2)
        return np.stack([xx, xy, xy, yy], axis=1)


def _quat(yaw: float, pitch: float = 0.0) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``pitch`` about y then ``yaw`` about z."""
    cy, sy, cp, sp = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    return (-sy * sp, cy * sp, sy * cp, cy * cp)


class EpisodeBag:
    """Write one episode into the MCAP rosbag2 folder ``out`` (see the module doc); a context manager:
    the bag appears at ``out`` only when the block ends without an error."""

    def __init__(self, out: str | Path, *, camera: CameraConfig, cones_xy: np.ndarray, cone_classes: np.ndarray,
                 weathered: bool = False, images: str = "jpeg", noise: ConeNoise = ConeNoise(),
                 overwrite: bool = False) -> None:
        lib("weather-gym lap --bag")
        if images not in BAG_IMAGES:
            raise InputError(f"--bag-images must be one of {', '.join(BAG_IMAGES)}, got {images!r}")
        self.out, self.camera, self.weathered, self.images, self.noise = Path(out), camera, weathered, images, noise
        self.cones_xy = np.asarray(cones_xy, np.float64).reshape(-1, 2)
        self.cone_classes = np.asarray(cone_classes, np.int64).reshape(-1)
        self.overwrite = overwrite
        check_bag_output(self.out, "rosbag2", overwrite, what="--bag")
        self.store = typestore()
        self.counts: Counter = Counter()
        self._ctx: Any = None
        self._writer: Any = None
        self._conns: dict[str, Any] = {}

    @classmethod
    def for_env(cls, out: str | Path, env: Any, *, weathered: bool, images: str = "jpeg",
                noise: ConeNoise = ConeNoise(), overwrite: bool = False) -> EpisodeBag:
        """The bag of an episode of ``env`` (a ``ConeTrackEnv``, e.g. ``wrapped.unwrapped``: its camera and
        track's cones), opened: feed it with :meth:`add_step` and close it with ``__exit__``."""
        trk = env.track
        return cls(out, camera=env.config.camera, cones_xy=trk.cones_xy, cone_classes=trk.cone_classes,
                   weathered=weathered, images=images, noise=noise, overwrite=overwrite).__enter__()

    def add_step(self, env: Any, obs: Any, info: dict) -> None:
        """One env step (or the reset): the clear frame from ``env.clear_image``, the observation's
        (weathered) ``image`` and cone list, the pose, speed and yaw rate of ``info``, the odometry of the
        observation's ``state`` (speed, yaw rate, odom x, y, yaw)."""
        d = obs if isinstance(obs, dict) else {"image": obs}
        state = d.get("state")
        odom = None if state is None else np.asarray(state, np.float64)[2:5]
        self.add(float(info["time"]), clear=env.clear_image, weathered=d.get("image"), cones=d.get("cones"),
                 mask=d.get("mask"), pose=info["pose"], speed=float(info["speed"]), yaw_rate=float(info["yaw_rate"]),
                 odom=odom)

    # -------------------------------------------------------------------------------------- lifecycle
    def __enter__(self) -> EpisodeBag:
        self._ctx = bag_output(self.out, kind="rosbag2", overwrite=self.overwrite)
        inner = self._ctx.__enter__()
        try:
            rosbag2 = lib().rosbag2
            self._writer = rosbag2.Writer(inner, version=8, storage_plugin=rosbag2.StoragePlugin.MCAP)
            self._writer.open()
            suffix = "/compressed" if self.images == "jpeg" else ""
            img = "sensor_msgs/msg/CompressedImage" if self.images == "jpeg" else "sensor_msgs/msg/Image"
            topics = [("/camera/image_raw" + suffix, img), ("/camera/camera_info", "sensor_msgs/msg/CameraInfo"),
                      ("/perception/cones", CONE_ARRAY), ("/ground_truth/cones", CONE_ARRAY),
                      ("/odom", "nav_msgs/msg/Odometry"), ("/ground_truth/odom", "nav_msgs/msg/Odometry"),
                      ("/tf", "tf2_msgs/msg/TFMessage"), ("/tf_static", "tf2_msgs/msg/TFMessage")]
            if self.weathered:
                topics.insert(1, ("/camera/image_weathered" + suffix, img))
            latched = {"/ground_truth/cones", "/tf_static"}
            for name, msgtype in topics:
                self._conns[name] = self._writer.add_connection(
                    name, msgtype, typestore=self.store,
                    offered_qos_profiles=[latched_qos()] if name in latched else [])
        except BaseException as exc:
            self.__exit__(type(exc), exc, None)
            raise
        return self

    def __exit__(self, et: Any, ev: Any, tb: Any) -> None:
        ctx, self._ctx = self._ctx, None
        if ctx is None:
            return
        try:
            if self._writer is not None and self._writer.storage is not None:
                self._writer.close()
        except BaseException:
            if et is None:
                ctx.__exit__(OutputPathError, OutputPathError("bag not closed"), None)
                raise
        ctx.__exit__(et, ev, tb)

    # -------------------------------------------------------------------------------------- messages
    def _write(self, topic: str, ns: int, msg: Any) -> None:
        conn = self._conns[topic]
        self._writer.write(conn, ns, self.store.serialize_cdr(msg, conn.msgtype))
        self.counts[topic] += 1

    def _image(self, rgb: np.ndarray, ns: int) -> Any:
        if self.images == "raw":
            return rgb_to_image(self.store, np.ascontiguousarray(rgb), "rgb8", stamp_ns=ns, frame_id="camera_optical")
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            raise OutputPathError(f"{self.out}: a camera frame could not be encoded as JPEG")
        return self.store.types["sensor_msgs/msg/CompressedImage"](
            header=header(self.store, ns, "camera_optical"), format="jpeg", data=buf.reshape(-1))

    def _camera_info(self, ns: int) -> Any:
        c = self.camera
        k = np.array([c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1], np.float64)
        p = np.array([c.fx, 0, c.cx, 0, 0, c.fy, c.cy, 0, 0, 0, 1, 0], np.float64)
        t = self.store.types
        roi = t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return t["sensor_msgs/msg/CameraInfo"](header=header(self.store, ns, "camera_optical"), height=c.height,
                                               width=c.width, distortion_model="plumb_bob", d=np.zeros(5),
                                               k=k, r=np.eye(3).reshape(-1), p=p, binning_x=0, binning_y=0, roi=roi)

    def _cones(self, ns: int, frame: str, xy: np.ndarray, classes: np.ndarray, cov: np.ndarray) -> Any:
        t = self.store.types
        point, cone = t["geometry_msgs/msg/Point"], t["eufs_msgs/msg/ConeWithCovariance"]
        arrays: dict[str, list[Any]] = {f: [] for f in CONE_FIELDS}
        for (x, y), cls, cv in zip(xy, classes, cov, strict=True):
            field = CONE_FIELDS[int(cls)] if 0 <= int(cls) < 4 else CONE_FIELDS[4]
            arrays[field].append(cone(point=point(x=float(x), y=float(y), z=0.0), covariance=np.asarray(cv, np.float64)))
        return t[CONE_ARRAY](header=header(self.store, ns, frame), **arrays)

    def _transform(self, ns: int, parent: str, child: str, xyz: Sequence[float], q: Sequence[float]) -> Any:
        t = self.store.types
        return t["geometry_msgs/msg/TransformStamped"](
            header=header(self.store, ns, parent), child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                rotation=t["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])))

    def _odometry(self, ns: int, frame: str, pose: Sequence[float] | np.ndarray, speed: float, yaw_rate: float) -> Any:
        t = self.store.types
        x, y, yaw = (float(v) for v in pose)
        q = _quat(yaw)
        v3 = t["geometry_msgs/msg/Vector3"]
        return t["nav_msgs/msg/Odometry"](
            header=header(self.store, ns, frame), child_frame_id="base_footprint",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                                 orientation=t["geometry_msgs/msg/Quaternion"](
                                                     x=q[0], y=q[1], z=q[2], w=q[3])),
                covariance=np.zeros(36)),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](linear=v3(x=float(speed), y=0.0, z=0.0),
                                                   angular=v3(x=0.0, y=0.0, z=float(yaw_rate))),
                covariance=np.zeros(36)))

    def add(self, time_s: float, *, clear: np.ndarray | None = None, weathered: np.ndarray | None = None,
            cones: np.ndarray | None = None, mask: np.ndarray | None = None, pose: Sequence[float],
            speed: float, yaw_rate: float, odom: Sequence[float] | np.ndarray | None = None) -> None:
        """One step at sim time ``time_s``: the clear and weathered frames, the cone list (``(N, 14)``
        rows of :data:`~weather_gym.perception.cones.CONE_FIELDS` with its ``mask``), the true ``pose``
        (x, y, yaw in the map), ``speed`` and ``yaw_rate``, and the car's odometry pose ``odom``."""
        ns = int(round(time_s * 1e9))
        first = not self.counts
        if first:
            cam = self.camera
            self._write("/tf_static", ns, self.store.types["tf2_msgs/msg/TFMessage"](transforms=[self._transform(
                ns, "base_footprint", "camera_link", (cam.mount_x, 0.0, cam.mount_height),
                _quat(0.0, math.radians(cam.pitch_deg))),
                self._transform(ns, "camera_link", "camera_optical", (0.0, 0.0, 0.0), OPTICAL)]))
            self._write("/ground_truth/cones", ns, self._cones(ns, "map", self.cones_xy, self.cone_classes,
                                                                np.zeros((len(self.cones_xy), 4))))
        suffix = "/compressed" if self.images == "jpeg" else ""
        if clear is not None:
            self._write("/camera/image_raw" + suffix, ns, self._image(clear, ns))
            self._write("/camera/camera_info", ns, self._camera_info(ns))
        if weathered is not None and self.weathered:
            self._write("/camera/image_weathered" + suffix, ns, self._image(weathered, ns))
        if cones is not None and mask is not None:
            rows = np.asarray(cones, np.float64)[np.asarray(mask).astype(bool)]
            classes = np.argmax(rows[:, :4], axis=1) if len(rows) else np.zeros(0, np.int64)
            cov = (self.noise.covariance(rows[:, FIELD["range"]], rows[:, FIELD["bearing"]]) if len(rows)
                   else np.zeros((0, 4)))
            xy = rows[:, [FIELD["x_body"], FIELD["y_body"]]]
            self._write("/perception/cones", ns, self._cones(ns, "base_footprint", xy, classes, cov))
        self._write("/ground_truth/odom", ns, self._odometry(ns, "map", pose, speed, yaw_rate))
        self._write("/odom", ns, self._odometry(ns, "odom", odom if odom is not None else pose, speed, yaw_rate))
        x, y, yaw = (float(v) for v in pose)
        self._write("/tf", ns, self.store.types["tf2_msgs/msg/TFMessage"](
            transforms=[self._transform(ns, "map", "base_footprint", (x, y, 0.0), _quat(yaw))]))
