"""Import a camera topic of a ROS bag into the project's COCO layout: ``weather-gym dataset import rosbag``.

:func:`import_rosbag` reads a rosbag2 bag (SQLite or MCAP storage; the bag folder or its storage file)
or a ROS 1 ``.bag``, decodes the frames of one ``sensor_msgs/Image`` (rgb8, bgr8, rgba8, bgra8, mono8)
or ``sensor_msgs/CompressedImage`` (JPEG, PNG) topic, picks them by time window and every Nth, and writes
``OUT/images/000000.png ...`` (lossless PNG of the decoded frame; grey frames as three equal channels)
and ``OUT/annotations.json``, as the other importers do (:mod:`weather_gym.lab.datasets.importers`: the
same ``--resume`` / ``--overwrite`` rules, marker and lock).

Each image record keeps the frame's ``stamp_ns`` (header stamp) and ``bag_time_ns`` (when the bag
received it), ``source_file`` (``TOPIC@BAG_TIME``), and the camera ``intrinsics`` from the latest
``sensor_msgs/CameraInfo`` before it (the topic beside the image topic, e.g. ``/cam/camera_info`` for
``/cam/image_raw``), unless ``--intrinsics`` gives them.

**No labels**: cone topics in a bag (``eufs_msgs/ConeArrayWithCovariance``, ``fs_msgs/Track``) hold
positions in the car's or the map's frame; turning them into boxes needs the camera's mounting (TF) and
each cone's visibility, which this import does not attempt. The dataset has no boxes: the gap
workflow's same-camera mode and ``weather-gym degrade`` take it as it is; scoring a detector on it
needs labels from a labelling tool (then import that tool's export).

Example:
    >>> import tempfile
    >>> import_rosbag(tempfile.mkdtemp() + "/nothing.mcap", tempfile.mkdtemp() + "/out")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.MissingInputError: bag .../nothing.mcap not found
"""

from __future__ import annotations

import hashlib
import os
from collections import Counter
from pathlib import Path
from typing import Any

from tqdm import tqdm

from weather_gym.camera.config import CameraConfig
from weather_gym.core._io import atomic_write_json, write_image
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.lab.datasets.coco import ANNOTATIONS
from weather_gym.lab.datasets.importers import (
    PARTIAL,
    _check_resume,
    _clear_but_marker,
    _condition,
    import_folder,
    parse_intrinsics,
)
from weather_gym.perception.labels import CATEGORIES, SmallRule
from weather_gym.ros.bags import open_bag
from weather_gym.ros.camera import ALL_FRAMES, Window, camera_frames, intrinsics_of
from weather_gym.ros.messages import CONE_ARRAY

__all__ = ["NO_LABELS", "import_rosbag"]

NO_LABELS = ("none: a bag's cone topics hold positions in the car's or map's frame, and projecting them into "
             "boxes needs the camera's mounting (TF) and visibility, which the import does not attempt")


def _bag_id(bag: Path) -> str:
    """Size and time of every file of the bag (a resumed import must read the same bag)."""
    files = sorted(p for p in bag.rglob("*") if p.is_file()) if bag.is_dir() else [bag]
    h = hashlib.sha256()
    for p in files:
        st = p.stat()
        h.update(f"{p.name}\0{st.st_size}\0{st.st_mtime_ns}\n".encode("utf-8", "surrogateescape"))
    return h.hexdigest()[:16]


def import_rosbag(bag: str | os.PathLike, out: str | os.PathLike, *, topic: str | None = None,
                  window: Window = ALL_FRAMES, camera_info: str | None = None, condition: str | None = None,
                  severity: int | None = None, intrinsics: Any = None, detector: Any = None,
                  overwrite: bool = False, resume: bool = False, progress: bool = False) -> dict[str, Any]:
    """Import the camera ``topic`` of ``bag`` into the COCO folder ``out``; returns a summary dict.

    ``topic``: the image topic (None: the bag's only one). ``window``: which frames (time window, every
    Nth). ``camera_info``: the CameraInfo topic (None: the one beside the image topic, if any; ``""``:
    none). ``intrinsics``: ``fx,fy,cx,cy`` that replace the bag's. The rest as
    :func:`~weather_gym.lab.datasets.importers.import_dataset`.
    """
    given, out = Path(bag), Path(out)
    window.check()
    if resume and overwrite:
        raise InputError("--resume continues an interrupted import, --overwrite starts again: pass one of them")
    if not given.exists():
        raise MissingInputError(f"bag {given} not found")
    src = Path(os.path.realpath(given))
    cond, sev = _condition(condition, severity)
    given_k = parse_intrinsics(intrinsics)
    with import_folder(out, src, overwrite, resume) as state, open_bag(src) as b:
        return _import(b, src, out, state, topic=topic, window=window, camera_info=camera_info, cond=cond,
                       sev=sev, given_k=given_k, detector=detector, progress=progress)


def _import(b: Any, src: Path, out: Path, state: str, *, topic: str | None, window: Window,  # noqa: C901
            camera_info: str | None, cond: str | None, sev: int | None, given_k: dict[str, float] | None,
            detector: Any, progress: bool) -> dict[str, Any]:
    t = b.image_topic(topic)
    info_topic = b.camera_info_topic(t.name) if camera_info is None else (camera_info or None)
    if info_topic is not None and info_topic not in b.topics:
        raise FileFormatError(f"--camera-info {info_topic}: not in {src} (topics: {b.summary()})")
    settings = {"topic": t.name, "start_s": window.start_s, "end_s": window.end_s, "every": window.every,
                "camera_info": info_topic, "condition": cond, "severity": sev, "intrinsics": given_k}
    ident = {"format": "rosbag", "source": str(src), **settings, "source_files": _bag_id(src)}
    if state == "resume":
        _check_resume(out, ident)
    images: list[dict[str, Any]] = []
    sizes: Counter = Counter()
    encodings: Counter = Counter()
    n_kept = 0
    total = -(-t.count // window.every) if window.start_s is None and window.end_s is None else None
    for fr in tqdm(camera_frames(b, t.name, window, info_topic=info_topic), total=total, desc="import",
                   unit="frame", disable=not progress):
        i = len(images)
        if i == 0:  # the marker goes in with the first frame: a bag without frames in the window leaves nothing
            atomic_write_json(out / PARTIAL, {"identity": ident}, overwrite=state != "new")
            if state == "replace":
                _clear_but_marker(out)
        h, w = fr.rgb.shape[:2]
        name = f"{i:06d}.png"
        dest = out / "images" / name
        if state == "resume" and dest.is_file():
            n_kept += 1
        else:
            write_image(dest, fr.rgb, overwrite=state == "resume")
        rec: dict[str, Any] = {"id": i, "file_name": f"images/{name}", "width": w, "height": h,
                               "source_file": f"{t.name}@{fr.bag_ns}", "stamp_ns": fr.stamp_ns,
                               "bag_time_ns": fr.bag_ns, "message_index": fr.index}
        k = given_k or intrinsics_of(fr.camera_info)
        if k is not None:
            try:
                cam = CameraConfig.from_intrinsics(w, h, **k)
            except ValueError as exc:
                raise FileFormatError(f"{src}: {t.name} frame at {fr.bag_ns} ns: {exc}") from None
            rec["intrinsics"] = {n: float(v) for n, v in k.items()}
            rec["camera"] = cam.to_dict()
        if cond is not None:
            rec["condition"], rec["severity"] = cond, sev
        images.append(rec)
        sizes[(w, h)] += 1
        encodings[fr.encoding] += 1
    if not images:
        raise FileFormatError(f"{src}: no frames of {t.name} in the window"
                              f" ({window.start_s or 0:g} s .. {'end' if window.end_s is None else f'{window.end_s:g} s'}"
                              f" after the bag's start; the topic has {t.count} messages)")
    rules = {s: SmallRule.for_image(s, detector) for s in sizes}
    size = next(iter(sizes)) if len(sizes) == 1 else None
    cone_topics = b.topics_of(CONE_ARRAY) + b.topics_of("fs_msgs/msg/Track")
    info: dict[str, Any] = {
        "description": "imported from a ROS bag by weather-gym dataset import rosbag", "origin": "import",
        "format": "rosbag", "layout": f"{b.kind} ({b.storage}) topic {t.name} ({t.msgtype})", "source": str(src),
        "topic": t.name, "msgtype": t.msgtype, "encodings": dict(encodings), "camera_info": info_topic,
        "window": {"start_s": window.start_s, "end_s": window.end_s, "every": window.every},
        "labels": NO_LABELS, "cone_topics_not_imported": cone_topics,
        "too_small": rules[size].to_dict() if size is not None else
        {"per_size": {f"{w}x{h}": r.min_height_px for (w, h), r in sorted(rules.items())}},
        "size": None if size is None else list(size), "sizes": {f"{w}x{h}": n for (w, h), n in sorted(sizes.items())},
        "intrinsics": "given" if given_k else ("camera_info" if any("intrinsics" in r for r in images) else "unknown"),
    }
    if size is not None:
        info["min_box_height_px"] = rules[size].min_height_px
    if cond is not None:
        info["condition"], info["severity"] = cond, sev
    atomic_write_json(out / ANNOTATIONS, {"info": info, "images": images, "annotations": [],
                                          "categories": CATEGORIES}, overwrite=state != "new")
    (out / PARTIAL).unlink()
    return {"out": str(out), "frames": len(images), "size": info["size"], "sizes": info["sizes"],
            "topic": t.name, "msgtype": t.msgtype, "kind": b.kind, "storage": b.storage,
            "encodings": dict(encodings), "camera_info": info_topic, "intrinsics": info["intrinsics"],
            "first_stamp_ns": images[0]["stamp_ns"], "last_stamp_ns": images[-1]["stamp_ns"],
            "cone_topics": cone_topics, "condition": cond, "severity": sev,
            "resumed": n_kept if state == "resume" else None}
