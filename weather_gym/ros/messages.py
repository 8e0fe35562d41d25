"""The ROS 2 messages weather-gym reads and writes, and camera frames to and from them (no ROS install).

* :func:`typestore`: the message types of a ROS 2 distribution (rosbags' built-in store, Humble by
  default) plus the Formula Student cone messages below, registered from their ``.msg`` text.
* :data:`CONE_MSGS`: ``eufs_msgs/ConeWithCovariance`` (``geometry_msgs/Point point``, ``float64[4]
  covariance``: the x-y covariance, row major) and ``eufs_msgs/ConeArrayWithCovariance`` (a header and
  five arrays ``blue_cones``, ``yellow_cones``, ``orange_cones``, ``big_orange_cones``,
  ``unknown_color_cones``), as published by EUFS (``eufs_msgs``, MIT).
* :func:`image_to_rgb` / :func:`rgb_to_image`: ``sensor_msgs/Image`` (encodings :data:`ENCODINGS`,
  row padding ``step`` honoured) and ``sensor_msgs/CompressedImage`` (JPEG, PNG) to an RGB ``uint8``
  array and back, in the message's own encoding.

Example:
    >>> import numpy as np
    >>> ts = typestore()
    >>> Image = ts.types["sensor_msgs/msg/Image"]
    >>> rgb = np.arange(8 * 12 * 3, dtype=np.uint8).reshape(8, 12, 3)
    >>> msg = rgb_to_image(ts, rgb, "bgr8", stamp_ns=1_500_000_000)
    >>> msg.encoding, msg.step, bool((image_to_rgb(msg, "sensor_msgs/msg/Image") == rgb).all())
    ('bgr8', 36, True)
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from weather_gym.core.errors import FileFormatError
from weather_gym.core.limits import check_image_size
from weather_gym.ros._deps import lib

__all__ = ["COMPRESSED", "CONE_ARRAY", "CONE_FIELDS", "CONE_MSGS", "ENCODINGS", "IMAGE", "IMAGE_TYPES",
           "compressed", "header", "image_alpha", "image_to_rgb", "msgtype_name", "rgb_to_image", "stamp_of", "typestore"]

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
IMAGE_TYPES = (IMAGE, COMPRESSED)
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
ODOMETRY = "nav_msgs/msg/Odometry"
CONE_ARRAY = "eufs_msgs/msg/ConeArrayWithCovariance"
CONE_FIELDS = ("blue_cones", "yellow_cones", "orange_cones", "big_orange_cones", "unknown_color_cones")
"""The arrays of a ``ConeArrayWithCovariance``; the first four are weather-gym's cone classes in order."""

CONE_MSGS = {
    "eufs_msgs/msg/ConeWithCovariance": "geometry_msgs/Point point\nfloat64[4] covariance\n",
    CONE_ARRAY: "std_msgs/Header header\n" + "".join(f"eufs_msgs/ConeWithCovariance[] {f}\n" for f in CONE_FIELDS),
}

ENCODINGS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1, "8UC1": 1, "8UC3": 3, "8UC4": 4}
"""``sensor_msgs/Image`` encodings read and written (channels); 8UC3/8UC4 are taken as BGR(A), as
cv_bridge does. Other encodings (16-bit, Bayer, YUV) are refused with their name."""


def typestore(distro: str = "humble") -> Any:
    """rosbags' typestore of ROS 2 ``distro`` (foxy, humble, jazzy...) with the cone messages registered."""
    rb = lib()
    try:
        store = rb.get_typestore(rb.Stores[f"ROS2_{distro.upper()}"])
    except KeyError:
        raise FileFormatError(f"unknown ROS 2 distribution {distro!r}; expected one of "
                              f"{', '.join(s.name[5:].lower() for s in rb.Stores if s.name.startswith('ROS2_'))}") from None
    types: dict[str, Any] = {}
    for name, text in CONE_MSGS.items():
        types.update(rb.get_types_from_msg(text, name))
    store.register(types)
    return store


def msgtype_name(msgtype: str) -> str:
    """``sensor_msgs/Image`` (ROS 1 spelling) -> ``sensor_msgs/msg/Image``; ROS 2 names unchanged."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def stamp_of(msg: Any) -> int:
    """The header stamp of ``msg`` in nanoseconds."""
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def image_to_rgb(msg: Any, msgtype: str, *, where: str = "") -> np.ndarray:
    """A ``sensor_msgs/Image`` or ``CompressedImage`` -> RGB ``uint8`` (H, W, 3); alpha dropped, grey
    repeated into three channels. ``where`` names the message in errors."""
    if msgtype_name(msgtype) == COMPRESSED:
        buf = np.frombuffer(bytes(msg.data), np.uint8)
        bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR) if buf.size else None
        if bgr is None:
            raise FileFormatError(f"{where}: compressed image (format {msg.format!r}, {buf.size} bytes) could not "
                                  "be decoded (expected JPEG or PNG)")
        check_image_size(bgr.shape, what=where)
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    enc = str(msg.encoding)
    if enc not in ENCODINGS:
        raise FileFormatError(f"{where}: image encoding {enc!r} is not supported; expected one of "
                              f"{', '.join(ENCODINGS)} (8 bits per channel)")
    h, w, c = int(msg.height), int(msg.width), ENCODINGS[enc]
    check_image_size((h, w, 3), what=where)
    step = int(msg.step)
    data = np.asarray(msg.data, np.uint8).reshape(-1)
    if step < w * c or data.size < step * h:
        raise FileFormatError(f"{where}: {w}x{h} {enc} image needs step >= {w * c} and {w * c * h} bytes, got "
                              f"step {step} and {data.size} bytes")
    img = data[: step * h].reshape(h, step)[:, : w * c].reshape(h, w, c)
    if c == 1:
        return np.repeat(img, 3, axis=2)
    if enc in ("rgb8", "rgba8"):
        return np.ascontiguousarray(img[..., :3])
    return np.ascontiguousarray(img[..., 2::-1])  # BGR(A) -> RGB


def rgb_to_image(store: Any, rgb: np.ndarray, encoding: str, *, like: Any = None, stamp_ns: int = 0,
                 frame_id: str = "camera") -> Any:
    """An RGB frame as a ``sensor_msgs/Image`` of ``encoding``. ``like``: a message whose header (and
    alpha channel, for rgba8/bgra8) the new one keeps; else a header of ``stamp_ns`` and ``frame_id``."""
    c = ENCODINGS.get(encoding)
    if c is None:
        raise FileFormatError(f"cannot write image encoding {encoding!r}; expected one of {', '.join(ENCODINGS)}")
    h, w = rgb.shape[:2]
    if c == 1:
        out = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)[..., None]
    else:
        out = rgb if encoding in ("rgb8", "rgba8") else rgb[..., ::-1]
        if c == 4:
            alpha = (image_alpha(like) if like is not None else None)
            alpha = np.full((h, w, 1), 255, np.uint8) if alpha is None else alpha
            out = np.concatenate([out, alpha], axis=2)
    head = like.header if like is not None else header(store, stamp_ns, frame_id)
    return store.types[IMAGE](header=head, height=h, width=w, encoding=encoding,
                              is_bigendian=int(getattr(like, "is_bigendian", 0)) if like is not None else 0,
                              step=w * c, data=np.ascontiguousarray(out).reshape(-1))


def image_alpha(msg: Any) -> np.ndarray | None:
    """The alpha channel (H, W, 1) of an rgba8/bgra8 ``sensor_msgs/Image``, else None."""
    if getattr(msg, "encoding", None) not in ("rgba8", "bgra8", "8UC4"):
        return None
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    return np.asarray(msg.data, np.uint8).reshape(-1)[: step * h].reshape(h, step)[:, 3: w * 4: 4][..., None].copy()


def compressed(store: Any, rgb: np.ndarray, fmt: str, *, like: Any, quality: int = 95) -> Any:
    """An RGB frame as a ``sensor_msgs/CompressedImage`` in the format of ``fmt`` (``png`` when the format
    names png, else JPEG of ``quality``), keeping ``like``'s header and format string."""
    png = "png" in fmt.lower()
    ok, buf = cv2.imencode(".png" if png else ".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                           [] if png else [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise FileFormatError(f"cannot encode a {rgb.shape[1]}x{rgb.shape[0]} frame as {'PNG' if png else 'JPEG'}")
    return store.types[COMPRESSED](header=like.header, format=fmt, data=buf.reshape(-1))


def header(store: Any, stamp_ns: int, frame_id: str) -> Any:
    """A ``std_msgs/Header`` of ``stamp_ns`` (nanoseconds) and ``frame_id``."""
    t = store.types
    cls = t["std_msgs/msg/Header"]
    stamp = t["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))
    extra = {"seq": 0} if "seq" in getattr(cls, "__dataclass_fields__", {}) else {}  # a ROS 1 store's header
    return cls(stamp=stamp, frame_id=frame_id, **extra)
