"""Reading ROS bags without ROS: rosbag2 (SQLite ``.db3`` or MCAP storage, a bag folder or its one
storage file) and ROS 1 ``.bag`` files, through ``rosbags``' reader, with typed errors.

* :func:`open_bag`: the opened reader (:class:`Bag`); a missing, truncated or corrupt bag raises
  :class:`~weather_gym.core.errors.MissingInputError` / :class:`~weather_gym.core.errors.FileFormatError` naming
  it, while it is opened or later while its messages are read (:meth:`Bag.messages`).
* :meth:`Bag.image_topic`: the camera topic (``sensor_msgs/Image`` or ``CompressedImage``) named, or the
  bag's only one; :meth:`Bag.camera_info_topic`: its ``camera_info`` beside it.
* Message types the bag does not describe (no definition in the bag, none in the typestore) are not
  read: :meth:`Bag.describe` says so, so that callers skip them with a note.

Example:
    >>> import tempfile, pathlib
    >>> with open_bag(pathlib.Path(tempfile.mkdtemp()) / "missing.mcap") as bag:
    ...     pass
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.MissingInputError: bag .../missing.mcap not found
"""

from __future__ import annotations

import os
import sqlite3
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.ros._deps import lib
from weather_gym.ros.messages import CAMERA_INFO, IMAGE_TYPES, msgtype_name, typestore

__all__ = ["BAG_SUFFIXES", "Bag", "bag_kind", "open_bag"]

BAG_SUFFIXES = (".bag", ".mcap", ".db3")
"""Bag files: ROS 1 ``.bag``, a rosbag2 storage file; a rosbag2 bag is also a folder with metadata.yaml."""


def bag_kind(path: str | os.PathLike) -> str | None:
    """``rosbag1``, ``rosbag2`` (a folder with metadata.yaml, a ``.mcap`` or ``.db3`` file) or None."""
    p = Path(path)
    if p.is_dir():
        return "rosbag2" if (p / "metadata.yaml").is_file() else None
    suffix = p.suffix.lower()
    return "rosbag1" if suffix == ".bag" else "rosbag2" if suffix in (".mcap", ".db3") else None


def _read_errors() -> tuple[type[Exception], ...]:
    """What the bag libraries raise for a damaged bag (beside their own error classes)."""
    rb = lib()
    return (rb.AnyReaderError, rb.rosbag1.ReaderError, rb.rosbag2.ReaderError, sqlite3.Error, struct.error,
            EOFError, ValueError, KeyError, IndexError, AssertionError, UnicodeDecodeError, OverflowError)


@dataclass(frozen=True)
class Topic:
    """A topic of a bag: name, message type (ROS 2 spelling), message count, connections."""

    name: str
    msgtype: str
    count: int
    connections: tuple[Any, ...]


class Bag:
    """An opened bag (see :func:`open_bag`): its topics, storage and messages."""

    def __init__(self, path: Path, reader: Any) -> None:
        self.path, self.reader = path, reader
        self.kind = "rosbag1" if not reader.is2 else "rosbag2"
        self.store = typestore()
        topics: dict[str, list[Any]] = {}
        for c in reader.connections:
            topics.setdefault(c.topic, []).append(c)
        self.topics = {name: Topic(name, msgtype_name(cs[0].msgtype), sum(c.msgcount for c in cs), tuple(cs))
                       for name, cs in sorted(topics.items())}

    @property
    def storage(self) -> str:
        """``sqlite3`` or ``mcap`` for a rosbag2 bag, ``rosbag1`` for a ROS 1 bag."""
        if self.kind == "rosbag1":
            return "rosbag1"
        st = self.reader.readers[0].storage  # a bag folder's reader, or the storage file's own
        st = (getattr(st, "storages", None) or [st])[0]
        return "mcap" if "mcap" in type(st).__name__.lower() else "sqlite3"

    @property
    def start_ns(self) -> int:
        return int(self.reader.start_time)

    @property
    def end_ns(self) -> int:
        return int(self.reader.end_time)

    def summary(self) -> str:
        """``/topic (type, N)`` for every topic."""
        return ", ".join(f"{t.name} ({t.msgtype}, {t.count})" for t in self.topics.values())

    def image_topics(self) -> list[str]:
        return [t.name for t in self.topics.values() if t.msgtype in IMAGE_TYPES]

    def image_topic(self, topic: str | None) -> Topic:
        """The camera topic ``topic`` (checked), or the bag's only image topic when None."""
        images = self.image_topics()
        if topic is None:
            if len(images) != 1:
                raise InputError(f"{self.path}: {'no' if not images else len(images)} image topics "
                                 f"({', '.join(images) or 'none of type sensor_msgs/Image or CompressedImage'}); "
                                 f"name the camera with --topic. Topics: {self.summary()}")
            topic = images[0]
        if topic not in self.topics:
            raise InputError(f"--topic {topic}: not in {self.path}; its image topics: {', '.join(images) or 'none'} "
                             f"(all topics: {self.summary()})")
        t = self.topics[topic]
        if t.msgtype not in IMAGE_TYPES:
            raise InputError(f"--topic {topic} carries {t.msgtype}, not sensor_msgs/Image or CompressedImage; "
                             f"image topics: {', '.join(images) or 'none'}")
        return t

    def camera_info_topic(self, image_topic: str) -> str | None:
        """The ``sensor_msgs/CameraInfo`` topic beside ``image_topic`` (``/cam/image_raw[/compressed]`` ->
        ``/cam/camera_info``), or the bag's only one, else None."""
        base = image_topic.removesuffix("/compressed").rsplit("/", 1)[0]
        infos = [t.name for t in self.topics.values() if t.msgtype == CAMERA_INFO]
        near = [n for n in infos if n == f"{base}/camera_info"]
        return near[0] if near else (infos[0] if len(infos) == 1 else None)

    def topics_of(self, msgtype: str) -> list[str]:
        return [t.name for t in self.topics.values() if t.msgtype == msgtype]

    def known(self, msgtype: str) -> bool:
        """Can messages of ``msgtype`` be decoded (a definition in the bag or in the typestore)?"""
        return msgtype_name(msgtype) in self.reader.typestore.types or msgtype_name(msgtype) in self.store.types

    def deserialize(self, raw: bytes, msgtype: str, where: str) -> Any:
        """Decode one message (the bag's own definition first, else the typestore's)."""
        try:
            if msgtype in self.reader.typestore.types:
                return self.reader.deserialize(raw, msgtype)
            name = msgtype_name(msgtype)
            return (self.store.deserialize_cdr(raw, name) if self.kind == "rosbag2"
                    else self.store.deserialize_ros1(raw, name))
        except _read_errors() as exc:
            raise FileFormatError(f"{where}: cannot decode a {msgtype} message ({exc})") from None

    def messages(self, topics: Sequence[str] = (), start: int | None = None,
                 stop: int | None = None) -> Iterator[tuple[Any, int, bytes]]:
        """(connection, receive time ns, raw bytes) of ``topics`` (all when empty), in time order; a
        damaged bag raises :class:`FileFormatError` naming it."""
        conns = [c for t in topics for c in self.topics[t].connections]
        it = self.reader.messages(connections=conns, start=start, stop=stop)
        while True:
            try:
                item = next(it)
            except StopIteration:
                return
            except _read_errors() as exc:
                raise FileFormatError(f"{self.path}: the bag is damaged or truncated; reading its messages failed "
                                      f"({type(exc).__name__}: {exc})") from None
            yield item


class _Opened:
    def __init__(self, path: Path) -> None:
        self.path = path
        self.bag: Bag | None = None

    def __enter__(self) -> Bag:
        rb = lib(f"reading the bag {self.path}")
        p = self.path
        if not p.exists():
            raise MissingInputError(f"bag {p} not found")
        kind = bag_kind(p)
        if kind is None:
            raise InputError(f"{p}: not a ROS bag; expected a rosbag2 folder (with metadata.yaml), a .mcap or .db3 "
                             "rosbag2 file, or a ROS 1 .bag file")
        reader = rb.AnyReader([p], default_typestore=typestore())
        errors: tuple[type[Exception], ...] = (*_read_errors(), OSError)
        try:
            reader.open()
        except errors as exc:
            if isinstance(exc, PermissionError):
                raise
            raise FileFormatError(f"{p}: not a readable {kind} bag: it is damaged, truncated or of an unknown "
                                  f"layout ({type(exc).__name__}: {exc})") from None
        self.bag = Bag(p, reader)
        return self.bag

    def __exit__(self, *exc: Any) -> None:
        if self.bag is not None:
            try:
                self.bag.reader.close()
            except _read_errors():
                pass


def open_bag(path: str | os.PathLike) -> _Opened:
    """``with open_bag(path) as bag:``: the bag opened for reading (see the module doc)."""
    return _Opened(Path(path))
