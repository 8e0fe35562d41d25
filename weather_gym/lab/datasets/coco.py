"""COCO datasets of rendered cone frames: validated reading (``load_coco``) and resumable writing.

Layout (see ``docs/architecture.md``)::

    DIR/annotations.json      COCO: images, annotations, categories (blue, yellow, orange, big_orange)
    DIR/images/000000.png     RGB frames
    DIR/depth/000000.png      z-depth, uint16 millimetres (saturates at 65.535 m = "far")

Image records carry ``track``, ``pose`` [x, y, yaw], ``speed``, ``yaw_rate``, ``camera``
(CameraConfig fields), ``depth_file``, ``look`` (so the view can be re-rendered) and ``seed``.
Annotations carry ``bbox`` [x, y, w, h] (visible part, from the segmentation mask), ``area``
(box area), ``category_id`` (class id + 1), ``iscrowd`` (1 = shorter than
``MIN_BOX_HEIGHT_PX``, ignored in training and scoring), ``range``, ``bearing``, ``cone_id``,
``pixels`` (visible pixel count).

Imported datasets (``weather-gym dataset import``) also have ignore regions (annotations with
``ignore``: the source class that was not mapped, and ``any_class``: they ignore detections of
every class), per-record ``intrinsics`` / ``camera`` / ``condition`` / ``severity``, and the
too-small rule in ``info.too_small``. An ignore mask (``info.ignore_mask``, per record
``ignore_mask``; see ``weather_gym.lab.datasets.masks``) is applied by ``gt(i)``'s ``ignore_mask``.

Example:
    >>> import numpy as np, tempfile
    >>> from weather_gym.lab.datasets.coco import CocoWriter, load_coco
    >>> d = tempfile.mkdtemp()
    >>> with CocoWriter(d) as w:
    ...     _ = w.add(np.zeros((8, 12, 3), np.uint8), {"track": "demo"},
    ...               {"boxes": np.array([[1, 1, 5, 7.]]), "classes": np.array([0])})
    >>> ds = load_coco(d)
    >>> len(ds), ds.gt(0)["classes"].tolist(), ds.gt(0)["iscrowd"].tolist()
    (1, [0], [1])
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core._confine import confined
from weather_gym.core._io import resolve_inside
from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import FileFormatError, MissingInputError
from weather_gym.core.limits import check_image_size
from weather_gym.lab.datasets.coco_files import (
    ANNOTATIONS,
    DEPTH_SCALE,
    JOURNAL,
    read_depth_png,
    read_image,
    read_mask,
    record_path,
    write_depth_png,
)
from weather_gym.lab.datasets.coco_writer import CocoWriter
from weather_gym.perception.labels import xywh_to_xyxy
from weather_gym.tracks import track_file_part

__all__ = ["ANNOTATIONS", "DEPTH_SCALE", "JOURNAL", "CocoDataset", "CocoWriter", "load_coco", "read_image",
           "read_depth_png", "record_path", "record_track_file", "write_depth_png"]


def record_track_file(root: str | os.PathLike, record: dict) -> tuple[str, str, Path] | None:
    """The cone CSV an image record's ``track`` names: ``(prefixes, path as written, path resolved inside
    the dataset folder root)``, checked like every file of a record (:func:`record_path`); the prefixes
    are the spec's ``reverse:`` / ``mirror:``. None when the track is a name (``peanut``, ``random:SEED``)
    or absent."""
    part = track_file_part(record.get("track"))
    if part is None:
        return None
    return part[0], part[1], record_path(root, {**record, "track": part[1]}, "track")


class CocoDataset:
    """A validated COCO cone dataset. Index ``i`` is the position in ``images`` (not the COCO id).

    ``image(i)``, ``depth(i)`` (None without a depth file), ``annotations(i)``, ``gt(i)`` (arrays:
    ``boxes`` xyxy, ``classes``, ``iscrowd``, ``ranges``, ``bearings``, ``cone_ids``),
    ``record(i)`` and ``render_view(i)`` (re-render the same pose with the same look).
    """

    def __init__(self, root: Path, data: dict, cache_images: bool = False) -> None:
        self.root = Path(root)
        self.cache_images = cache_images
        self._image_cache: dict[int, np.ndarray] = {}
        self.data = data
        self.images: list[dict] = data["images"]
        self.categories: list[dict] = data["categories"]
        self._cat_to_class = {c["id"]: CONE_CLASSES.index(c["name"]) for c in self.categories}
        self._anns: dict[int, list[dict]] = {im["id"]: [] for im in self.images}
        for a in data["annotations"]:
            self._anns[a["image_id"]].append(a)
        self._renderer: Any = None  # a ViewRenderer, made at the first re-rendered view
        self._masks: dict[str, np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.images)

    def __iter__(self) -> Iterator[dict]:
        return iter(self.images)

    def __repr__(self) -> str:
        return f"CocoDataset({str(self.root)!r}, images={len(self)}, annotations={len(self.data['annotations'])})"

    @property
    def annotations_path(self) -> Path:
        return self.root / ANNOTATIONS

    def record(self, i: int) -> dict:
        return self.images[i]

    def image_path(self, i: int) -> Path:
        """Where frame ``i`` is (inside the dataset folder: checked, see :func:`load_coco`)."""
        return record_path(self.root, self.images[i], "file_name")

    def track_spec(self, i: int) -> str | None:
        """The track of frame ``i`` as :func:`weather_gym.tracks.load_track` takes it: a registered name,
        ``random:SEED``, or the (confined, resolved) path of a cone CSV inside the dataset folder (after its
        ``reverse:`` / ``mirror:`` prefixes, if any)."""
        track = self.images[i].get("track")
        part = record_track_file(self.root, self.images[i])
        return track if part is None else part[0] + str(part[2])

    def image(self, i: int) -> np.ndarray:
        """RGB uint8 frame ``i`` (read-only when ``cache_images`` keeps decoded frames in memory); a frame
        whose size is not its record's ``width`` x ``height`` is a :class:`FileFormatError` (its boxes,
        masks and camera are in the record's pixels)."""
        if not self.cache_images:
            return self._read_checked(i)
        img = self._image_cache.get(i)
        if img is None:
            img = self._read_checked(i)
            img.setflags(write=False)
            self._image_cache[i] = img
        return img

    def _read_checked(self, i: int) -> np.ndarray:
        rec, path = self.images[i], self.image_path(i)
        img = read_image(path)
        if img.shape[:2] != (rec["height"], rec["width"]):
            raise FileFormatError(f"{self.annotations_path}: image {rec['id']} is {rec['width']}x{rec['height']} "
                                  f"(width x height) but its file {path} is {img.shape[1]}x{img.shape[0]}; fix the "
                                  "record or the file")
        return img

    def depth(self, i: int) -> np.ndarray | None:
        """Depth of frame ``i`` in metres (float32), or None when the record has no ``depth_file``."""
        rel = self.images[i].get("depth_file")
        return None if not rel else read_depth_png(record_path(self.root, self.images[i], "depth_file"))

    def annotations(self, i: int) -> list[dict]:
        return self._anns[self.images[i]["id"]]

    @property
    def info(self) -> dict:
        """The ``info`` object of ``annotations.json`` (``{}`` when absent)."""
        info = self.data.get("info")
        return info if isinstance(info, dict) else {}

    def _mask(self, rel: str, rec: dict) -> np.ndarray:
        m = self._masks.get(rel)
        if m is None:
            m = read_mask(resolve_inside(self.root, rel, what=f"{self.annotations_path}: ignore mask"),
                          (int(rec["width"]), int(rec["height"])))
            m.setflags(write=False)
            self._masks[rel] = m
        if m.shape != (int(rec["height"]), int(rec["width"])):
            raise FileFormatError(f"{self.root / rel}: ignore mask is {m.shape[1]}x{m.shape[0]} but image {rec['id']} "
                             f"is {rec['width']}x{rec['height']}")
        return m

    @property
    def has_ignore_mask(self) -> bool:
        return bool(self.info.get("ignore_mask")) or any(r.get("ignore_mask") for r in self.images)

    def ignore_mask(self, i: int) -> np.ndarray | None:
        """Boolean ``(H, W)`` ignore mask of frame ``i`` (dataset-wide OR per-frame), or None (read-only)."""
        rec = self.images[i]
        rels = [r for r in (self.info.get("ignore_mask"), rec.get("ignore_mask")) if r]
        if not rels:
            return None
        if len(rels) == 1:
            return self._mask(rels[0], rec)
        both = self._mask(rels[0], rec) | self._mask(rels[1], rec)
        both.setflags(write=False)
        return both

    def gt(self, i: int) -> dict[str, np.ndarray]:
        """Ground truth of frame ``i`` as arrays (the in-memory format ``evaluate`` also takes).

        Keys: ``boxes`` (xyxy), ``classes``, ``iscrowd``, ``ignore`` / ``any_class`` (ignore regions),
        ``ranges``, ``bearings``, ``cone_ids``, and ``ignore_mask`` when the frame has one.
        """
        anns = self.annotations(i)
        boxes = xywh_to_xyxy(np.array([a["bbox"] for a in anns], dtype=np.float64).reshape(-1, 4))
        out: dict[str, np.ndarray] = {
            "boxes": boxes.astype(np.float32),
            "classes": np.array([self._cat_to_class[a["category_id"]] for a in anns], dtype=np.int64),
            "iscrowd": np.array([int(a.get("iscrowd", 0)) for a in anns], dtype=np.int64),
            "ignore": np.array([bool(a.get("ignore")) for a in anns], dtype=bool),
            "any_class": np.array([bool(a.get("any_class")) for a in anns], dtype=bool),
            "ranges": np.array([a.get("range", np.nan) for a in anns], dtype=np.float32),
            "bearings": np.array([a.get("bearing", np.nan) for a in anns], dtype=np.float32),
            "cone_ids": np.array([a.get("cone_id", -1) for a in anns], dtype=np.int64),
        }
        mask = self.ignore_mask(i)
        if mask is not None:
            out["ignore_mask"] = mask
        return out

    def camera(self, i: int):
        """The ``CameraConfig`` of frame ``i`` (default camera when the record has none)."""

        rec = self.images[i]
        cam = rec.get("camera")
        if cam:
            return CameraConfig(**cam)
        k = rec.get("intrinsics")
        if k:
            return CameraConfig.from_intrinsics(rec["width"], rec["height"], k["fx"], k["fy"], k["cx"], k["cy"])
        return CameraConfig().scaled(rec["width"], rec["height"])

    def render_view(self, i: int | dict) -> dict[str, Any]:
        """Re-render frame ``i`` (or an image record) at the same pose with the same look.

        Returns ``{"image", "depth", "gt"}``. Needs the simulator (PyBullet); envs are cached per
        (track, camera) until ``close()``.
        """

        if self._renderer is None:  # the simulator is imported only where a view is re-rendered
            from weather_gym.lab.datasets.render import ViewRenderer

            self._renderer = ViewRenderer()
        if isinstance(i, dict):
            rec = i
        else:
            rec = {**self.images[i], "track": self.track_spec(i)}
        return self._renderer.render(rec)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> CocoDataset:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _fail(path: Path, msg: str):
    raise FileFormatError(f"{path}: {msg}")


def _read_annotations(root: Path) -> tuple[Path, dict]:
    """``root``'s ``annotations.json`` (path, parsed object with its three lists checked)."""
    if not root.is_dir():
        raise MissingInputError(f"dataset folder {root} not found")
    path = root / ANNOTATIONS
    if not path.is_file():
        extra = " (an interrupted render left annotations.partial.jsonl: rerun it with --resume)" if (
            root / JOURNAL).exists() else ""
        raise MissingInputError(f"{path} not found: a COCO dataset folder needs annotations.json{extra}")
    confined(path, root)  # every file a dataset names is confined (record_path); its annotations.json too
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise FileFormatError(f"{path} is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        _fail(path, "expected a JSON object with images, annotations and categories")
    for key in ("images", "annotations", "categories"):
        if not isinstance(data.get(key), list):
            _fail(path, f"missing or invalid key {key!r} (expected a list)")
    return path, data


def _check_image(path: Path, root: Path, im: Any, ids: set, check_files: bool) -> None:
    """One image record: its keys and types, a unique id, and the files it names inside ``root``."""
    for key in ("id", "file_name", "width", "height"):
        if not isinstance(im, dict) or key not in im:
            _fail(path, f"image record {im!r} has no {key!r}")
    if not isinstance(im["id"], int) or isinstance(im["id"], bool):
        _fail(path, f"image record id {im['id']!r} is not an integer")
    if not isinstance(im["file_name"], str):
        _fail(path, f"image {im['id']}: 'file_name' must be a string, got {im['file_name']!r}")
    for key in ("width", "height"):
        if not isinstance(im[key], int) or isinstance(im[key], bool) or im[key] < 1:
            _fail(path, f"image {im['id']}: {key!r} must be a positive integer, got {im[key]!r}")
    check_image_size((im["height"], im["width"]), what=f"{path}: image {im['id']}")  # the one frame bound
    if im["id"] in ids:
        _fail(path, f"duplicate image id {im['id']}")
    ids.add(im["id"])
    f = record_path(root, im, "file_name")
    if im.get("depth_file") is not None:
        record_path(root, im, "depth_file")
    record_track_file(root, im)
    if im.get("ignore_mask") is not None:
        record_path(root, im, "ignore_mask")
    if check_files:
        if not f.is_file():
            raise MissingInputError(f"{path}: image {im['id']} points to {f}, which does not exist")
        if f.stat().st_size == 0:
            _fail(path, f"image {im['id']} file {f} is empty (0 bytes)")


def _check_annotation(path: Path, a: Any, ids: set, cat_ids: set) -> None:
    if not isinstance(a, dict):
        _fail(path, f"annotation {a!r} is not an object")
    if not isinstance(a.get("image_id"), int) or a["image_id"] not in ids:
        _fail(path, f"annotation {a.get('id')} refers to unknown image_id {a.get('image_id')!r}")
    if not isinstance(a.get("category_id"), int) or a["category_id"] not in cat_ids:
        _fail(path, f"annotation {a.get('id')} has unknown category_id {a.get('category_id')!r}")
    b = a.get("bbox")
    if (not isinstance(b, list) or len(b) != 4 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in b)
            or b[2] < 0 or b[3] < 0):
        _fail(path, f"annotation {a.get('id')} has an invalid bbox {b!r} (expected [x, y, w, h], w, h >= 0)")


def load_coco(root: str | os.PathLike, *, check_files: bool = True, cache_images: bool = False) -> CocoDataset:
    """Open and validate a COCO cone dataset folder.

    ``cache_images=True`` keeps decoded frames in memory (about 0.75 MB per 672x376 frame): for
    repeated scoring of the same frames (calibration sweeps).

    Raises ``FileNotFoundError`` for a missing folder, ``annotations.json`` or image file, and
    ``ValueError`` (naming the file and the offending key/value) for malformed annotations or empty
    image files.
    """
    root = Path(root)
    path, data = _read_annotations(root)
    for c in data["categories"]:
        if not isinstance(c, dict) or c.get("name") not in CONE_CLASSES or not isinstance(c.get("id"), int):
            _fail(path, f"category {c!r} is not one of {list(CONE_CLASSES)} with an integer id")
    cat_ids = {c["id"] for c in data["categories"]}
    ids: set = set()
    for im in data["images"]:
        _check_image(path, root, im, ids, check_files)
    for a in data["annotations"]:
        _check_annotation(path, a, ids, cat_ids)
    info: dict[str, Any] = data.get("info") if isinstance(data.get("info"), dict) else {}  # type: ignore[assignment]  # a dict: checked
    if info.get("ignore_mask") is not None:
        mask_file = resolve_inside(root, info["ignore_mask"], what=f"{path}: info.ignore_mask")
        if check_files and not mask_file.is_file():
            raise MissingInputError(f"{path}: info.ignore_mask points to {mask_file}, which does not exist")
    return CocoDataset(root, data, cache_images=cache_images)
