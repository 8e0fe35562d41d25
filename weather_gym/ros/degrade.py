"""Weather a ROS bag: a copy with the camera topic degraded frame by frame (``weather-gym degrade IN OUT``).

:func:`degrade_bag` reads the bag in time order and writes a new bag of the same kind and storage (a
rosbag2 folder with SQLite or MCAP storage, or a ROS 1 ``.bag``):

* the image topic (``sensor_msgs/Image`` or ``CompressedImage``) goes through one run of the weather
  (:meth:`~weather_gym.weather.Effect.start` with ``seed``: the bag is one episode, so persistent lens
  drops stay and grow from frame to frame), each message written back in its own encoding with its
  header (stamp, frame id) and receive time; compressed frames are re-encoded (JPEG of ``jpeg_quality``,
  or PNG when the format names png);
* the motion effects take the car's ``speed`` (``twist.linear.x``) and ``yaw_rate`` (``twist.angular.z``)
  from the latest ``nav_msgs/Odometry`` message before each frame, and ``fx`` from the
  ``sensor_msgs/CameraInfo`` beside the camera, when the bag has them;
* every other message is copied byte for byte with its receive time; each topic keeps its type, message
  definition and hash, serialization format and QoS profiles (``offered_qos_profiles``; ROS 1: caller
  id and latching). A topic whose type the bag does not describe (no definition, none in the typestore)
  cannot be written into a new bag: it is left out, and the result says so.

The new bag is written into a temporary folder beside ``out`` and moved into place when complete:
an error or Ctrl-C leaves nothing (a rerun starts again). The input is never the output; an existing
output is replaced only with ``overwrite`` (and only when it is a bag).

Example:
    >>> import tempfile
    >>> from weather_gym.weather import parse_weather
    >>> d = tempfile.mkdtemp()
    >>> degrade_bag(d + "/in.mcap", d + "/out", weather=parse_weather("droplets@2"))
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.MissingInputError: bag .../in.mcap not found
"""

from __future__ import annotations

import contextlib
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from weather_gym.core.errors import InputError, MissingInputError
from weather_gym.ros._deps import lib
from weather_gym.ros.bag_output import bag_output, check_bag_output
from weather_gym.ros.bags import Bag, bag_kind, open_bag
from weather_gym.ros.camera import intrinsics_of
from weather_gym.ros.messages import (
    CAMERA_INFO,
    COMPRESSED,
    ODOMETRY,
    compressed,
    image_to_rgb,
    msgtype_name,
    rgb_to_image,
)

__all__ = ["BagDegradeResult", "degrade_bag"]

ROSBAG2_VERSION = 8
"""metadata.yaml version of the rosbag2 bags written (rosbags writes 8 or 9; 8 is what ROS 2 Iron and Jazzy write)."""


@dataclass
class BagDegradeResult:
    """What :func:`degrade_bag` did: the topic weathered, frames, copied messages per topic, the
    odometry topic used (None: none), topics left out (with why), the output's kind and storage."""

    out: str
    topic: str
    frames: int = 0
    copied: Counter = field(default_factory=Counter)
    odometry: str | None = None
    camera_info: str | None = None
    left_out: dict[str, str] = field(default_factory=dict)
    kind: str = ""
    storage: str = ""
    first_ns: int | None = None
    last_ns: int | None = None


def _check_paths(src: Path, out: Path, kind: str, overwrite: bool) -> None:
    rs, ro = Path(os.path.realpath(src)), Path(os.path.realpath(out))
    if rs == ro or rs in ro.parents or ro in rs.parents:
        raise InputError(f"{out}: the output bag must not be the input bag, nor inside it or around it")
    check_bag_output(out, kind, overwrite)


def degrade_bag(src: str | os.PathLike, out: str | os.PathLike, *, weather: Any, topic: str | None = None,
                odometry: str | None = None, seed: int = 0, jpeg_quality: int = 95, overwrite: bool = False,
                progress: bool = False) -> BagDegradeResult:
    """Write ``out``: ``src`` with its camera ``topic`` weathered by ``weather`` (see the module doc).

    ``topic``: the image topic (None: the bag's only one). ``odometry``: the ``nav_msgs/Odometry`` topic
    for the motion effects (None: the bag's only one, if any; ``""``: none).
    """
    src, out = Path(src), Path(out)
    if not 1 <= int(jpeg_quality) <= 100:
        raise InputError(f"--jpeg-quality must be 1-100, got {jpeg_quality}")
    if not src.exists():
        raise MissingInputError(f"bag {src} not found")
    kind = bag_kind(src)
    if kind is None:
        raise InputError(f"{src}: not a ROS bag; expected a rosbag2 folder (with metadata.yaml), a .mcap or .db3 "
                         "rosbag2 file, or a ROS 1 .bag file")
    _check_paths(src, out, kind, overwrite)
    lib(f"weathering the bag {src}")
    with open_bag(src) as bag:
        t = bag.image_topic(topic)
        odom = _odometry_topic(bag, odometry)
        res = BagDegradeResult(str(out), t.name, odometry=odom, camera_info=bag.camera_info_topic(t.name),
                               kind=bag.kind, storage=bag.storage)
        with bag_output(out, kind=bag.kind, overwrite=overwrite) as inner:
            _write(bag, inner, res, weather.start(seed), jpeg_quality, progress)
    return res


def _odometry_topic(bag: Bag, odometry: str | None) -> str | None:
    odoms = bag.topics_of(ODOMETRY)
    if odometry == "":
        return None
    if odometry is None:
        if len(odoms) > 1:
            raise InputError(f"{bag.path}: {len(odoms)} odometry topics ({', '.join(odoms)}); name the car's with "
                             "--odometry (or --odometry '' for none)")
        return odoms[0] if odoms else None
    if odometry not in odoms:
        raise InputError(f"--odometry {odometry}: not a nav_msgs/Odometry topic of {bag.path} "
                         f"(odometry topics: {', '.join(odoms) or 'none'})")
    return odometry


def _open_writer(bag: Bag, inner: Path) -> Any:
    rb = lib()
    if bag.kind == "rosbag1":
        w = rb.rosbag1.Writer(inner)
    else:
        plugin = rb.rosbag2.StoragePlugin.MCAP if bag.storage == "mcap" else rb.rosbag2.StoragePlugin.SQLITE3
        w = rb.rosbag2.Writer(inner, version=ROSBAG2_VERSION, storage_plugin=plugin)
    w.open()
    return w


def _add_connection(w: Any, bag: Bag, conn: Any, res: BagDegradeResult) -> Any:
    """The output connection of ``conn`` (same type, definition, QoS), or None when it cannot be described."""
    msgdef, digest = conn.msgdef.data, conn.digest
    if not msgdef or not digest:
        name = msgtype_name(conn.msgtype)
        store = bag.reader.typestore if name in bag.reader.typestore.types else bag.store
        if name not in store.types:
            res.left_out[conn.topic] = f"type {conn.msgtype} has no definition in the bag or the typestore"
            return None
        if bag.kind == "rosbag1":
            msgdef, digest = store.generate_msgdef(name, ros_version=1)
        else:
            msgdef, digest = store.generate_msgdef(name, ros_version=2)[0], store.hash_rihs01(name)
    if bag.kind == "rosbag1":
        return w.add_connection(conn.topic, conn.msgtype, msgdef=msgdef, md5sum=digest,
                                callerid=conn.ext.callerid, latching=conn.ext.latching)
    return w.add_connection(conn.topic, conn.msgtype, msgdef=msgdef, rihs01=digest,
                            serialization_format=conn.ext.serialization_format,
                            offered_qos_profiles=conn.ext.offered_qos_profiles)


def _serialize(bag: Bag, msg: Any, msgtype: str) -> bytes:
    store = bag.reader.typestore if msgtype in bag.reader.typestore.types else bag.store
    name = msgtype if msgtype in store.types else msgtype_name(msgtype)
    return bytes(store.serialize_ros1(msg, name) if bag.kind == "rosbag1" else store.serialize_cdr(msg, name))


def _write(bag: Bag, inner: Path, res: BagDegradeResult, run: Any, quality: int, progress: bool) -> None:  # noqa: C901
    w = _open_writer(bag, inner)
    try:
        out_conn: dict[int, Any] = {}
        for conn in bag.reader.connections:
            c = _add_connection(w, bag, conn, res)
            if c is not None:
                out_conn[id(conn)] = c
        state: dict[str, float] = {}
        store = bag.reader.typestore if COMPRESSED in bag.reader.typestore.types else bag.store
        total = sum(t.count for t in bag.topics.values())
        for conn, ns, raw in tqdm(bag.messages(), total=total, desc="degrade", unit="msg", disable=not progress):
            oc = out_conn.get(id(conn))
            if oc is None:
                continue
            where = f"{bag.path}: {conn.topic} at {ns} ns"
            if conn.topic == res.odometry:
                tw = bag.deserialize(raw, conn.msgtype, where).twist.twist
                state["speed"], state["yaw_rate"] = float(tw.linear.x), float(tw.angular.z)
            elif conn.topic == res.camera_info and msgtype_name(conn.msgtype) == CAMERA_INFO:
                k = intrinsics_of(bag.deserialize(raw, conn.msgtype, where))
                if k is not None:
                    state["fx"] = k["fx"]
            if conn.topic != res.topic:
                w.write(oc, ns, raw)
                res.copied[conn.topic] += 1
                continue
            msg = bag.deserialize(raw, conn.msgtype, where)
            mtype = msgtype_name(conn.msgtype)
            rgb = run(image_to_rgb(msg, mtype, where=where), state=dict(state) or None)
            if mtype == COMPRESSED:
                new = compressed(store, rgb, str(msg.format), like=msg, quality=quality)
            else:
                new = rgb_to_image(store, rgb, str(msg.encoding), like=msg)
            w.write(oc, ns, _serialize(bag, new, conn.msgtype))
            res.frames += 1
            res.first_ns = ns if res.first_ns is None else res.first_ns
            res.last_ns = ns
    except BaseException:
        with contextlib.suppress(Exception):
            w.close()
        raise
    w.close()
