"""Camera frames out of a bag: the image topic decoded to RGB, picked by time window and every Nth,
with each frame's timestamps and the latest ``sensor_msgs/CameraInfo`` before it.

Example:
    >>> Window(start_s=1.0, end_s=2.0, every=2).check().every
    2
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.ros.bags import Bag
from weather_gym.ros.messages import CAMERA_INFO, image_to_rgb, msgtype_name, stamp_of

__all__ = ["ALL_FRAMES", "BagFrame", "Window", "camera_frames", "intrinsics_of"]


@dataclass(frozen=True)
class Window:
    """Which frames: those received ``start_s`` .. ``end_s`` seconds after the bag's first message
    (None: from the start / to the end), then every ``every``-th of them (the first one kept)."""

    start_s: float | None = None
    end_s: float | None = None
    every: int = 1

    def check(self) -> Window:
        if isinstance(self.every, bool) or not isinstance(self.every, int) or self.every < 1:
            raise InputError(f"--every must be an integer >= 1, got {self.every!r}")
        for name, v in (("--start", self.start_s), ("--end", self.end_s)):
            if v is not None and (not math.isfinite(v) or v < 0):
                raise InputError(f"{name} must be a number of seconds >= 0 from the bag's start, got {v!r}")
        if self.start_s is not None and self.end_s is not None and self.end_s <= self.start_s:
            raise InputError(f"--end {self.end_s} must be after --start {self.start_s}")
        return self

    def bounds(self, bag_start_ns: int) -> tuple[int | None, int | None]:
        """The window in bag receive time (ns): ``start`` inclusive, ``stop`` exclusive."""
        start, end = (None if s is None else bag_start_ns + round(s * 1e9) for s in (self.start_s, self.end_s))
        return start, end


@dataclass(frozen=True)
class BagFrame:
    """One camera frame: its index among the topic's messages in the window, receive time and header
    stamp (ns), the RGB image, the message's encoding (or compressed format) and the camera info."""

    index: int
    bag_ns: int
    stamp_ns: int
    rgb: np.ndarray
    encoding: str
    camera_info: Any = None


def intrinsics_of(info: Any) -> dict[str, float] | None:
    """``{fx, fy, cx, cy}`` from a ``CameraInfo``'s K (None when K is all zeros: an uncalibrated camera)."""
    if info is None:
        return None
    k = [float(v) for v in np.asarray(info.k if hasattr(info, "k") else info.K, np.float64).reshape(-1)]
    if len(k) != 9 or k[0] <= 0 or k[4] <= 0:
        return None
    return {"fx": k[0], "fy": k[4], "cx": k[2], "cy": k[5]}


ALL_FRAMES = Window()
"""Every frame of the topic."""


def camera_frames(bag: Bag, topic: str, window: Window = ALL_FRAMES, *,
                  info_topic: str | None = None) -> Iterator[BagFrame]:
    """The frames of the image ``topic`` in ``window`` (see :class:`Window`), decoded in time order."""
    t = bag.image_topic(topic)
    start, stop = window.bounds(bag.start_ns)
    topics = [t.name] + ([info_topic] if info_topic else [])
    info = None
    n = 0
    for conn, ns, raw in bag.messages(topics, start=None if info_topic else start, stop=stop):
        mtype = msgtype_name(conn.msgtype)
        where = f"{bag.path}: {conn.topic} at {ns} ns"
        if mtype == CAMERA_INFO:
            info = bag.deserialize(raw, conn.msgtype, where)
            continue
        if start is not None and ns < start:
            continue
        n += 1
        if (n - 1) % window.every:
            continue
        msg = bag.deserialize(raw, conn.msgtype, where)
        enc = getattr(msg, "encoding", None) or f"compressed {getattr(msg, 'format', '')}".strip()
        yield BagFrame(n - 1, int(ns), stamp_of(msg), image_to_rgb(msg, mtype, where=where), enc, info)
