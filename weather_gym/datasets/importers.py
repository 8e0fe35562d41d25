"""Import labelled camera recordings (KITTI, YOLO txt, COCO, Supervisely/FSOCO) into the project's COCO layout.

``weather-gym dataset import {kitti,yolo,coco,supervisely} SRC --out DIR`` (:func:`import_dataset`) reads
a folder of frames and labels, validates all of it first, then copies the frames (byte for byte) into
``DIR/images/`` and writes ``DIR/annotations.json``; nothing outside ``DIR`` is written.

* **Confinement**: every file read from SRC (frames, label and calibration files, ``classes.txt``,
  ``data.yaml``, JSON files, linked sub-folders) must resolve inside SRC (:mod:`weather_gym._confine`);
  a link that leads out is an error naming the link, and nothing is read through it. Text files must
  be UTF-8. Frames must lie within :func:`~weather_gym.limits.check_image_size` (checked from the
  header, before decoding).
* **Frames of several sizes** are kept, each record with its own ``width`` / ``height`` and the
  too-small rule at its size (``info.too_small.per_size``); ``--intrinsics`` and ``--mask`` need one size.
* **Label files without an image** are left out and listed (``info.labels_without_image``; the CLI
  warns); an image without its label file is an error.
* **Interrupted imports**: ``DIR/import.partial.json`` marks one (with the source, settings and
  source files it was made of); ``resume=True`` continues it (other settings are refused),
  ``overwrite=True`` starts again. A second import into ``DIR`` while one runs is refused (a lock).
* **Class map** (``--classes``): ``SOURCE=TARGET`` pairs, TARGET one of ``blue``, ``yellow``,
  ``orange``, ``big_orange`` or ``ignore``. Boxes of an ``ignore`` class become *ignore regions*:
  detections of any class on them are neither hits nor false positives, and the cone is not a
  miss. ``*=ignore`` maps every class not named. A class found in the labels that the map leaves
  out is an error (naming the file, the class and the map). The default map is
  :data:`DEFAULT_CLASSES` (FSOCO / FSKITTI names, ``unknown_cone`` an ignore region). YOLO classes
  are their names (``classes.txt``, ``obj.names`` or ``data.yaml``) or their indices.
* **KITTI**: rows ``type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score]``;
  a row whose 2D box is all zeros carries only a 3D box: it is left out (not a miss) and counted.
  When the frames have intrinsics and at least :data:`MIN_POSE_ROWS` rows carry both boxes, the
  camera's pose in the 3D frame is fitted to those rows and each 3D-only cone in view is projected
  into an *ignore region* (a detection on a real but unlabelled cone is then not a false positive).
  Range and bearing come from the 3D location when it is given (its frame is recognised from
  where the 2D boxes are: KITTI's camera frame, x right / z forward, or a vehicle frame,
  x forward / y left; ``location_frame`` forces one). Intrinsics from ``calib/*.txt`` (``P2``).
* **YOLO**: rows ``class cx cy w h`` normalised to the image; an empty label file is a frame
  without cones, a missing one an error. Layouts: ``images/`` + ``labels/`` (mirrored), or darknet's
  ``img.jpg`` + ``img.txt`` side by side anywhere under SRC (``classes.txt`` / ``obj.names`` at SRC).
* **Supervisely** (FSOCO): ``SRC/meta.json`` (classes) and per dataset ``DATASET/img/NAME`` with
  ``DATASET/ann/NAME.json`` (``size``, ``objects``); ``rectangle`` objects (``points.exterior``
  ``[[x1, y1], [x2, y2]]``, ``classTitle``) become boxes, other geometries are counted and left out.
  Frames are stored as ``images/DATASET/NAME``.
* **COCO**: one JSON file (``--annotations`` or the only ``*.json`` in SRC) with any category
  names; ``iscrowd`` boxes become ignore regions of their class.

Each image record carries ``width``, ``height``, ``source_file``, the camera ``intrinsics`` (``fx``,
``fy``, ``cx``, ``cy`` in pixels: from ``--intrinsics`` or calibration files; a principal point off
the centre is kept) and the matching ``camera``, and ``condition`` / ``severity`` when given
(``clear``, or a weather condition with severity 1-4: what ``weather-gym calibrate --measured DIR``
groups by). ``info.too_small`` states the too-small rule at the detector's input scale
(:class:`~weather_gym.perception.labels.SmallRule`).

Example:
    >>> from weather_gym.datasets.importers import parse_class_map
    >>> parse_class_map("blue_cone=blue,0=yellow,*=ignore")
    {'blue_cone': 'blue', '0': 'yellow', '*': 'ignore'}
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import shutil
import warnings
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from PIL import Image
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from weather_gym._confine import confined_file, read_bytes, read_text, walk_files
from weather_gym._io import atomic_write, atomic_write_json, file_id, resolve_inside
from weather_gym._lock import exclusive_folder
from weather_gym.camera_config import CameraConfig
from weather_gym.cone_spec import CONE_CLASSES
from weather_gym.datasets.coco import ANNOTATIONS
from weather_gym.datasets.masks import MASK_FILE, read_mask, write_mask
from weather_gym.errors import (
    FileFormatError,
    InputError,
    LimitError,
    MissingInputError,
    OutputExistsError,
    OutputPathError,
    OutsideRootError,
)
from weather_gym.limits import MAX_IMAGE_PIXELS, check_image_size
from weather_gym.perception.labels import CATEGORIES, DEFAULT_CLASSES, IGNORE, SmallRule, parse_class_map
from weather_gym.weather.presets import CONDITIONS, canonical_condition

__all__ = ["FORMATS", "DEFAULT_CLASSES", "IGNORE", "parse_class_map", "parse_intrinsics", "import_dataset"]

FORMATS = ("kitti", "yolo", "coco", "supervisely")
IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp")
_KITTI_DIRS = {"images": ("images", "image_2", "image"), "labels": ("labels", "label_2", "label"), "calib": ("calib",)}


# ------------------------------------------------------------------------------------ arguments
def parse_intrinsics(spec: str | Sequence[float] | Mapping[str, float] | None) -> dict[str, float] | None:
    """``"fx,fy,cx,cy"`` (pixels at the image size), a 4-sequence or a mapping -> ``{fx, fy, cx, cy}``."""
    if spec is None:
        return None
    if isinstance(spec, Mapping):
        vals = [spec.get(k) for k in ("fx", "fy", "cx", "cy")]
    elif isinstance(spec, str):
        vals = [v.strip() for v in spec.split(",")]
    else:
        vals = list(spec)
    try:
        nums = [float(v) for v in vals]
    except (TypeError, ValueError):
        nums = []
    if len(nums) != 4 or not all(math.isfinite(v) for v in nums) or not (0 < nums[0] <= 1e7 and 0 < nums[1] <= 1e7) \
            or not all(abs(v) <= 1e6 for v in nums[2:]):  # fx, fy within STATE_BOUNDS; cx, cy near the frame
        raise InputError(f"intrinsics {spec!r} (--intrinsics): expected fx,fy,cx,cy in pixels at the image size "
                         "(0 < fx, fy <= 1e7; |cx|, |cy| <= 1e6), e.g. 900.9,900.1,506.4,358.0")
    return dict(zip(("fx", "fy", "cx", "cy"), nums))


def _condition(condition: str | None, severity: int | None) -> tuple[str | None, int | None]:
    if condition is None:
        if severity is not None:
            raise InputError("--severity needs --condition (clear, or a weather condition such as droplets)")
        return None, None

    if condition.strip().lower() in ("clear", "ideal", "none"):
        if severity not in (None, 0):
            raise InputError(f"--condition {condition} is the clear reference: severity must be 0 or absent, got {severity}")
        return "clear", 0
    try:
        c = canonical_condition(condition.strip())
    except ValueError:
        raise InputError(f"--condition {condition!r}: expected clear or a weather condition "
                         f"({', '.join(CONDITIONS)}, or the effect names droplets, dim)") from None
    if severity is None or not 1 <= int(severity) <= 4:
        raise InputError(f"--condition {condition} needs --severity 1-4, got {severity}")
    return c, int(severity)


# ------------------------------------------------------------------------------------ reading sources
@dataclass
class _Box:
    cls: str
    box: tuple[float, float, float, float]  # xyxy pixels
    where: str
    range: float = math.nan
    bearing: float = math.nan
    crowd: bool = False
    location: tuple[float, float, float] | None = None
    size3d: tuple[float, float] | None = None  # KITTI (h, w) in metres


@dataclass
class _Frame:
    image: Path  # the resolved file (confined to the source folder)
    rel: str  # where it goes under OUT/images/
    source_file: str = ""  # the path under the source folder, as found there
    boxes: list[_Box] = field(default_factory=list)
    only3d: list[tuple[str, tuple[float, float, float], tuple[float, float, float], str]] = field(default_factory=list)
    intrinsics: dict[str, float] | None = None
    size: tuple[int, int] = (0, 0)
    stated_size: tuple[int, int] | None = None  # (w, h) the labels state (COCO, Supervisely)
    label: Path | None = None  # the label file, for the resume identity


@dataclass
class _Read:
    """What a reader found: frames, counts of rows left out, label files without an image, the layout."""

    frames: list[_Frame]
    stats: Counter = field(default_factory=Counter)
    unmatched: list[str] = field(default_factory=list)
    layout: str = ""


_NOT_LABELS = frozenset({"classes.txt", "train.txt", "val.txt", "valid.txt", "test.txt", "readme.txt", "license.txt"})
"""``.txt`` files of a darknet folder that are not label files."""


def _find_dir(src: Path, names: Sequence[str], what: str, required: bool = True) -> Path | None:
    for n in names:
        if (src / n).is_dir():
            return src / n
    if required:
        raise MissingInputError(f"{src}: no {what} folder (looked for {', '.join(n + '/' for n in names)})")
    return None


def _is_image(p: Path) -> bool:
    return p.suffix.lower() in IMAGE_EXTS


def _images_under(folder: Path, root: Path) -> list[Path]:
    files = [p for p in walk_files(folder, root) if _is_image(p)]
    if not files:
        raise MissingInputError(f"{folder}: no images ({', '.join(IMAGE_EXTS)})")
    return files


def _rel(path: Path, base: Path) -> str:
    return path.relative_to(base).as_posix()


def _check_box(x1: float, y1: float, x2: float, y2: float, where: str) -> tuple[float, float, float, float]:
    if not all(math.isfinite(v) for v in (x1, y1, x2, y2)):
        raise FileFormatError(f"{where}: box ({x1}, {y1}, {x2}, {y2}) is not finite")
    if x2 <= x1 or y2 <= y1:
        raise FileFormatError(f"{where}: box ({x1:g}, {y1:g}, {x2:g}, {y2:g}) is empty or inverted (expected x1 < x2, y1 < y2)")
    return (x1, y1, x2, y2)


def _floats(parts: Sequence[str], where: str, what: str) -> list[float]:
    try:
        return [float(v) for v in parts]
    except ValueError:
        raise FileFormatError(f"{where}: expected numbers for {what}, got {' '.join(parts)!r}") from None


def _frame(img: Path, rel: str, src: Path) -> _Frame:
    """A frame for the image ``img`` found under ``src``: resolved inside it (a link out is refused)."""
    return _Frame(confined_file(img, src), rel, _rel(img, src))


def _labelled(images: Path, labels: Path, src: Path, fmt: str, *, unmatched: list[str]) -> Iterator[tuple[Path, _Frame]]:
    """Each image under ``images`` with its label file (mirrored under ``labels``, ``.txt``) and a new frame;
    label files without an image are added to ``unmatched``."""
    imgs = _images_under(images, src)
    stems = {p.relative_to(images).with_suffix("") for p in imgs}
    unmatched += [_rel(p, src) for p in walk_files(labels, src)
                  if p.suffix == ".txt" and p.relative_to(labels).with_suffix("") not in stems]
    for img in imgs:
        lab = (labels / img.relative_to(images)).with_suffix(".txt")
        if not lab.is_file():
            raise MissingInputError(f"{img}: its {fmt} label file {lab} is missing (every image needs one; an "
                                    "empty file means no cones)")
        fr = _frame(img, _rel(img, images), src)
        fr.label = lab
        yield lab, fr


def _read_kitti(src: Path) -> _Read:
    images = _find_dir(src, _KITTI_DIRS["images"], "images")
    labels = _find_dir(src, _KITTI_DIRS["labels"], "labels")
    calib = _find_dir(src, _KITTI_DIRS["calib"], "calib", required=False)
    res = _Read([], layout=f"{images.name}/ + {labels.name}/")
    for lab, fr in _labelled(images, labels, src, "KITTI", unmatched=res.unmatched):
        for n, line in enumerate(read_text(lab, root=src).splitlines(), 1):
            parts = line.split()
            if not parts:
                continue
            where = f"{lab}:{n}"
            if len(parts) not in (15, 16):
                raise FileFormatError(f"{where}: a KITTI row has 15 values (type truncated occluded alpha x1 y1 x2 y2 "
                                 f"h w l x y z rotation_y) or 16 (with score), got {len(parts)}")
            v = _floats(parts[1:15], where, "the KITTI columns")
            x1, y1, x2, y2 = v[3:7]
            if x1 == y1 == x2 == y2 == 0.0:
                res.stats["rows without a 2D box (3D only): left out"] += 1
                if any(v[10:13]) and all(d > 0 for d in v[7:9]):  # (h, w, l), location: projected later
                    fr.only3d.append((parts[0], tuple(v[7:10]), tuple(v[10:13]), where))
                continue
            loc = tuple(v[10:13]) if any(v[7:13]) else None
            size3d = (v[7], v[8]) if v[7] > 0 and v[8] > 0 else None
            fr.boxes.append(_Box(parts[0], _check_box(x1, y1, x2, y2, where), where, location=loc, size3d=size3d))
        if calib is not None:
            fr.intrinsics = _kitti_calib((calib / fr.rel).with_suffix(".txt"), src)
        res.frames.append(fr)
    return res


def _kitti_calib(path: Path, src: Path) -> dict[str, float] | None:
    if not path.is_file():
        return None
    for n, line in enumerate(read_text(path, root=src).splitlines(), 1):
        key, _, rest = line.partition(":")
        if key.strip() in ("P2", "P_rect_02", "K"):
            v = _floats(rest.split(), f"{path}:{n}", key.strip())
            if key.strip() == "K" and len(v) == 9:
                return {"fx": v[0], "fy": v[4], "cx": v[2], "cy": v[5]}
            if len(v) == 12:
                return {"fx": v[0], "fy": v[5], "cx": v[2], "cy": v[6]}
            raise FileFormatError(f"{path}:{n}: {key.strip()} needs 12 values (3x4 projection) or K 9 values, got {len(v)}")
    raise FileFormatError(f"{path}: no P2 (or K) line with the camera intrinsics")


def _yolo_names(src: Path) -> list[str] | None:
    for name in ("classes.txt", "obj.names"):
        if (src / name).is_file() or (src / name).is_symlink():
            return [ln.strip() for ln in read_text(src / name, root=src).splitlines() if ln.strip()]
    for name in ("data.yaml", "dataset.yaml"):
        if (src / name).is_file() or (src / name).is_symlink():
            return _yaml_names(src / name, src)
    return None


def _yaml_names(path: Path, src: Path) -> list[str]:
    """``names`` of a YOLO data.yaml: a list (inline or block) or an index -> name mapping."""
    text = read_text(path, root=src)
    try:
        import yaml
    except ImportError:  # a minimal reader of the two usual forms
        names = _yaml_names_plain(text)
    else:
        try:
            data = yaml.safe_load(text)
        except (yaml.YAMLError, RecursionError) as exc:
            raise FileFormatError(f"{path} is not valid YAML: {exc}") from None
        names = data.get("names") if isinstance(data, dict) else None
    if isinstance(names, dict):
        try:
            names = [str(names[k]) for k in sorted(names, key=int)]
        except (TypeError, ValueError):
            raise FileFormatError(f"{path}: 'names' keys must be class indices 0, 1, ...") from None
    if not isinstance(names, list) or not names:
        raise FileFormatError(f"{path}: expected a 'names' list (or index: name mapping) of the classes")
    return [str(n) for n in names]


def _yaml_names_plain(text: str) -> list[str] | None:
    names, block = None, None
    for line in text.splitlines():
        s = line.split("#", 1)[0].rstrip()
        if s.startswith("names:"):
            rest = s[6:].strip()
            if rest.startswith("["):
                return [t.strip().strip("'\"") for t in rest.strip("[]").split(",") if t.strip()]
            block = []
            continue
        if block is not None:
            if not s.startswith((" ", "\t", "-")):
                break
            t = s.strip()
            if t.startswith("-"):
                block.append(t[1:].strip().strip("'\""))
            elif ":" in t:
                block.append(t.split(":", 1)[1].strip().strip("'\""))
    return names if names is not None else block


def _yolo_rows(lab: Path, src: Path, fr: _Frame, names: list[str] | None) -> None:
    w, h = fr.size
    for n, line in enumerate(read_text(lab, root=src).splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        where = f"{lab}:{n}"
        if len(parts) != 5:
            raise FileFormatError(f"{where}: a YOLO row has 5 values (class cx cy w h, normalised to the image), "
                             f"got {len(parts)}")
        try:
            idx = int(parts[0])
        except ValueError:
            raise FileFormatError(f"{where}: class must be an integer index, got {parts[0]!r}") from None
        cx, cy, bw, bh = _floats(parts[1:], where, "cx cy w h")
        if not all(-0.01 <= v <= 1.01 for v in (cx, cy, bw, bh)):
            raise FileFormatError(f"{where}: cx cy w h must be normalised to [0, 1], got {' '.join(parts[1:])}")
        if names is not None and not 0 <= idx < len(names):
            raise FileFormatError(f"{where}: class index {idx} is outside the {len(names)} class names of {src}")
        cls = names[idx] if names is not None else str(idx)
        box = ((cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h)
        fr.boxes.append(_Box(cls, _check_box(*box, where), where))


def _read_yolo(src: Path) -> _Read:
    """``images/`` + ``labels/`` (mirrored), or the darknet layout: ``img.jpg`` and ``img.txt`` side by side."""
    names = _yolo_names(src)
    if (src / "images").is_dir() and (src / "labels").is_dir():
        res = _Read([], layout="images/ + labels/")
        pairs = list(_labelled(src / "images", src / "labels", src, "YOLO", unmatched=res.unmatched))
    else:
        res = _Read([], layout="labels beside the images (darknet)")
        files = walk_files(src, src)
        imgs = [p for p in files if _is_image(p)]
        if not imgs:
            raise MissingInputError(f"{src}: no images ({', '.join(IMAGE_EXTS)}): expected images/ + labels/, or "
                                    "images with their .txt label files beside them (darknet)")
        stems = {p.with_suffix("") for p in imgs}
        res.unmatched += [_rel(p, src) for p in files if p.suffix == ".txt" and p.with_suffix("") not in stems
                          and p.name.lower() not in _NOT_LABELS]
        pairs = []
        for img in imgs:
            lab = img.with_suffix(".txt")
            if not lab.is_file() and not lab.is_symlink():
                raise MissingInputError(f"{img}: its YOLO label file {lab} is missing (in the darknet layout every "
                                        "image needs a .txt beside it; an empty file means no cones)")
            fr = _frame(img, _rel(img, src), src)
            fr.label = lab
            pairs.append((lab, fr))
    for lab, fr in pairs:
        fr.size = _image_size(fr, src)
        _yolo_rows(lab, src, fr, names)
        res.frames.append(fr)
    return res


def _json(path: Path, src: Path | None, what: str) -> Any:
    text = read_text(path, root=src)
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise FileFormatError(f"{path} is not a valid {what} JSON file: {exc}") from None


def _read_coco(src: Path, annotations: Path | None) -> _Read:
    if annotations is None:
        cands = sorted(p for p in src.iterdir() if p.suffix == ".json" and (p.is_file() or p.is_symlink()))
        if len(cands) != 1:
            raise MissingInputError(f"{src}: expected exactly one COCO *.json file, found "
                                    f"{len(cands)} ({', '.join(p.name for p in cands) or 'none'}); pass --annotations")
        annotations = cands[0]
        data = _json(annotations, src, "COCO")
    else:  # named on the command line: the user's choice, read where it is
        if not annotations.is_file():
            raise MissingInputError(f"--annotations {annotations} not found")
        data = _json(annotations, None, "COCO")
    for key in ("images", "annotations", "categories"):
        if not isinstance(data, dict) or not isinstance(data.get(key), list):
            raise FileFormatError(f"{annotations}: missing or invalid key {key!r} (expected a list)")
    cats = {}
    for c in data["categories"]:
        if not isinstance(c, dict) or not _is_id(c.get("id")) or "name" not in c:
            raise FileFormatError(f"{annotations}: category {c!r} needs an id (an integer or a string) and a name")
        cats[c["id"]] = str(c["name"])
    # the frames are looked for beside the JSON (when it lies in SRC), in SRC and in SRC/images, never outside SRC
    near = Path(os.path.realpath(annotations.parent))
    bases = list(dict.fromkeys(([near] if near.is_relative_to(src) else []) + [src, src / "images"]))
    frames, by_id, seen = [], {}, set()
    for im in data["images"]:
        if not isinstance(im, dict) or not _is_id(im.get("id")) or not isinstance(im.get("file_name"), str):
            raise FileFormatError(f"{annotations}: image record {im!r} needs an id (an integer or a string) and a "
                                  "file_name")
        rel = im["file_name"]
        what = f"{annotations}: image {im['id']} 'file_name'"
        if not rel or "\x00" in rel or Path(rel).is_absolute():
            raise OutsideRootError(f"{what}: {rel!r} must be a path relative to the images' folder inside {src}")
        cands = [Path(os.path.normpath(b / rel)) for b in bases]
        cands = [c for c in cands if _lexically_inside(c, src)]
        if not cands:
            raise OutsideRootError(f"{what}: {rel!r} leads outside {src}; the frames must lie inside the source folder")
        path = next((c for c in cands if c.is_file() or c.is_symlink()), None)
        if path is None:
            raise MissingInputError(f"{annotations}: image {im['id']} file {rel} not found under "
                                    f"{' or '.join(str(b) for b in bases)}")
        if ".." in Path(rel).parts:
            rel = _rel(path, Path(os.path.normpath(src)))
        if im["id"] in by_id:
            raise FileFormatError(f"{annotations}: duplicate image id {im['id']!r}")
        if rel in seen:
            raise FileFormatError(f"{annotations}: image {im['id']}: file {rel} is listed twice")
        seen.add(rel)
        fr = _frame(path, Path(rel).as_posix(), src)
        fr.stated_size = _stated_size(im.get("width"), im.get("height"), f"{annotations}: image {im['id']}")
        frames.append(fr)
        by_id[im["id"]] = fr
    for a in data["annotations"]:
        where = f"{annotations}: annotation {a.get('id') if isinstance(a, dict) else a!r}"
        if not isinstance(a, dict) or not _is_id(a.get("image_id")) or a["image_id"] not in by_id:
            raise FileFormatError(f"{where} refers to an unknown image_id")
        if not _is_id(a.get("category_id")) or a["category_id"] not in cats:
            raise FileFormatError(f"{where} has an unknown category_id {a.get('category_id')!r}")
        b = a.get("bbox")
        if not isinstance(b, list) or len(b) != 4:
            raise FileFormatError(f"{where}: bbox {b!r} is not [x, y, w, h]")
        x, y, w, h = _floats([str(v) for v in b], where, "bbox")
        box = _Box(cats[a["category_id"]], _check_box(x, y, x + w, y + h, where), where, crowd=bool(a.get("iscrowd")))
        rng = a.get("range")
        box.range = float(rng) if isinstance(rng, int | float) and not isinstance(rng, bool) else math.nan
        by_id[a["image_id"]].boxes.append(box)
    return _Read(frames, layout=f"COCO {annotations.name}")


def _is_id(v: Any) -> bool:
    return isinstance(v, int | str) and not isinstance(v, bool)


def _lexically_inside(path: Path, src: Path) -> bool:
    base = Path(os.path.normpath(os.path.abspath(src)))
    p = Path(os.path.normpath(os.path.abspath(path)))
    return p == base or p.is_relative_to(base)


def _stated_size(w: Any, h: Any, where: str) -> tuple[int, int] | None:
    """The ``width``/``height`` a label file states (None when it states none)."""
    if w is None and h is None:
        return None
    if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (w, h)):
        raise FileFormatError(f"{where}: width and height must be positive integers, got {w!r} x {h!r}")
    return int(w), int(h)


def _read_supervisely(src: Path) -> _Read:
    """A Supervisely project (FSOCO): ``meta.json`` (classes) and per dataset ``img/`` + ``ann/<image>.json``;
    rectangles become boxes, other geometries are counted and left out."""
    meta_file = src / "meta.json"
    if not meta_file.is_file() and not meta_file.is_symlink():
        raise MissingInputError(f"{src}: no meta.json (a Supervisely project holds meta.json and dataset folders "
                                "with img/ and ann/)")
    meta = _json(meta_file, src, "Supervisely meta")
    classes = meta.get("classes") if isinstance(meta, dict) else None
    if not isinstance(classes, list) or not all(isinstance(c, dict) and isinstance(c.get("title"), str)
                                                for c in classes):
        raise FileFormatError(f"{meta_file}: expected 'classes': a list of objects with a 'title'")
    titles = {c["title"] for c in classes}
    datasets = [src] if (src / "img").is_dir() else []
    datasets += [d for d in sorted(src.iterdir()) if d.is_dir() and (d / "img").is_dir()]
    if not datasets:
        raise MissingInputError(f"{src}: no dataset folders with img/ and ann/ (Supervisely layout: "
                                "PROJECT/meta.json, PROJECT/DATASET/img/NAME, PROJECT/DATASET/ann/NAME.json)")
    res = _Read([], layout="Supervisely project (meta.json, DATASET/img/ + DATASET/ann/)")
    for ds in datasets:
        img_dir, ann_dir = ds / "img", ds / "ann"
        if not ann_dir.is_dir():
            raise MissingInputError(f"{ds}: img/ without ann/ (every image needs ann/NAME.json)")
        imgs = _images_under(img_dir, src)
        names = {_rel(p, img_dir) for p in imgs}
        res.unmatched += [_rel(p, src) for p in walk_files(ann_dir, src)
                          if p.suffix == ".json" and _rel(p, ann_dir)[:-5] not in names]
        prefix = "" if ds == src else f"{ds.name}/"
        for img in imgs:
            ann = ann_dir / f"{_rel(img, img_dir)}.json"
            if not ann.is_file() and not ann.is_symlink():
                raise MissingInputError(f"{img}: its Supervisely annotation {ann} is missing (every image needs one)")
            fr = _frame(img, prefix + _rel(img, img_dir), src)
            fr.label = ann
            _supervisely_objects(ann, src, fr, titles, res.stats)
            res.frames.append(fr)
    return res


def _supervisely_objects(ann: Path, src: Path, fr: _Frame, titles: set[str], stats: Counter) -> None:
    data = _json(ann, src, "Supervisely annotation")
    if not isinstance(data, dict) or not isinstance(data.get("objects"), list):
        raise FileFormatError(f"{ann}: expected an object with 'size' and an 'objects' list")
    size = data.get("size")
    if not isinstance(size, dict):
        raise FileFormatError(f"{ann}: 'size' must be {{\"height\": H, \"width\": W}}, got {size!r}")
    fr.stated_size = _stated_size(size.get("width"), size.get("height"), f"{ann}: size")
    for k, obj in enumerate(data["objects"]):
        where = f"{ann}: object {k}"
        if not isinstance(obj, dict) or not isinstance(obj.get("classTitle"), str):
            raise FileFormatError(f"{where}: expected an object with a 'classTitle' and a 'geometryType'")
        if obj["classTitle"] not in titles:
            raise FileFormatError(f"{where}: class {obj['classTitle']!r} is not among the classes of "
                                  f"{src / 'meta.json'}")
        geom = obj.get("geometryType")
        if geom != "rectangle":
            stats[f"objects of geometry {geom} (not a box): left out"] += 1
            continue
        pts = (obj.get("points") or {}).get("exterior") if isinstance(obj.get("points"), dict) else None
        if not (isinstance(pts, list) and len(pts) == 2 and all(isinstance(p, list) and len(p) == 2 for p in pts)):
            raise FileFormatError(f"{where}: a rectangle needs points.exterior [[x1, y1], [x2, y2]], got {pts!r}")
        (xa, ya), (xb, yb) = (_floats([str(v) for v in p], where, "points.exterior") for p in pts)
        box = _check_box(min(xa, xb), min(ya, yb), max(xa, xb), max(ya, yb), where)
        fr.boxes.append(_Box(obj["classTitle"], box, where))


_GREY_MODES = frozenset({"1", "L", "LA", "I", "I;16", "I;16B", "I;16L", "F"})
"""Pillow modes of single-channel frames (refused: the detector and the effects take colour frames)."""


def _image_size(fr: _Frame, src: Path) -> tuple[int, int]:
    """(width, height) of a frame as every reader decodes it (an EXIF rotation applied, as labelling tools
    show it): the header is read first and the size bound checked (:func:`~weather_gym.limits.check_image_size`)
    before the frame is decoded."""
    where = fr.image if not fr.source_file else src / fr.source_file
    mode = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(fr.image) as im:
                (w, h), mode = im.size, im.mode
                if im.getexif().get(0x0112) in (5, 6, 7, 8):  # EXIF orientation: turned by 90 degrees
                    w, h = h, w
    except Image.DecompressionBombError:
        raise LimitError(f"{where}: image is larger than {MAX_IMAGE_PIXELS / 1e6:.0f} MP (the most supported)") from None
    except (OSError, SyntaxError, ValueError):
        w = h = None  # not a format Pillow reads: OpenCV decides below
    if w is not None:
        check_image_size((h, w), what=str(where))
    if mode is None:  # Pillow could not tell the channels: OpenCV's undecorated decode does
        raw = cv2.imread(str(fr.image), cv2.IMREAD_UNCHANGED)
        channels = None if raw is None or raw.size == 0 else (1 if raw.ndim == 2 else raw.shape[2])
    else:
        channels = 1 if mode in _GREY_MODES else 3
    if channels is not None and channels not in (3, 4):
        raise FileFormatError(f"image file {where} has {channels} channel(s); expected colour (RGB) frames")
    img = cv2.imread(str(fr.image), cv2.IMREAD_COLOR)  # as weather_gym.datasets.coco.read_image decodes it
    if img is None or img.size == 0:
        raise FileFormatError(f"image file {where} could not be decoded as an image")
    check_image_size(img.shape, what=str(where))
    return int(img.shape[1]), int(img.shape[0])


# ------------------------------------------------------------------------------------ geometry
def _location_frame(frames: list[_Frame], requested: str) -> tuple[str, str]:
    """Which frame KITTI 3D locations are in: ``camera`` (x right, z forward) or ``vehicle`` (x forward,
    y left), recognised from which puts the cones on the side of the image their 2D box is on."""
    if requested not in ("auto", "camera", "vehicle", "none"):
        raise InputError(f"location frame must be auto, camera, vehicle or none, got {requested!r}")
    if requested != "auto":
        return requested, f"{requested} (given)"
    votes = Counter()
    n = 0
    for fr in frames:
        w = fr.size[0]
        cx = fr.intrinsics["cx"] if fr.intrinsics else w / 2.0
        for b in fr.boxes:
            if b.location is None:
                continue
            u = 0.5 * (b.box[0] + b.box[2]) - cx
            if abs(u) < 0.05 * w:
                continue
            x, y, z = b.location
            n += 1
            votes["camera"] += (np.sign(x) == np.sign(u)) and z > 0
            votes["vehicle"] += (np.sign(-y) == np.sign(u)) and x > 0
    if n < 5:
        return "none", f"none ({n} cones with both a 3D location and a 2D box off the centre: too few to tell)"
    best, hits = max(votes.items(), key=lambda t: t[1]) if votes else ("none", 0)
    if hits < 0.9 * n:
        return "none", (f"none (neither frame puts >= 90 % of {n} cones on the side of their 2D box: camera "
                        f"{votes['camera']}, vehicle {votes['vehicle']})")
    return best, f"{best} (recognised: {hits} of {n} cones on the side of their 2D box)"


MIN_POSE_ROWS = 8
"""Rows with both a 2D box and a 3D location needed to fit the camera pose for projecting 3D-only cones."""


def _camera_axes(loc: np.ndarray, h: np.ndarray, frame: str) -> tuple[np.ndarray, np.ndarray]:
    """Bottom and top centre of cones in camera-like axes (x right, y down, z forward)."""
    x, y, z = loc.T
    if frame == "camera":  # KITTI: the location is the bottom centre, y down
        bottom = np.c_[x, y, z]
    else:  # vehicle: x forward, y left, z up
        bottom = np.c_[-y, -z, x]
    top = bottom - np.c_[np.zeros_like(h), h, np.zeros_like(h)]
    return bottom, top


def _project(pose: np.ndarray, k: Mapping[str, float], loc: np.ndarray, hw: np.ndarray, frame: str):
    """xyxy boxes and forward distances of cones (locations ``loc``, sizes ``hw`` = (h, w)) under ``pose``
    (rotation vector, translation of the 3D frame into the camera)."""

    rot = Rotation.from_rotvec(pose[:3])
    bottom, top = (rot.apply(p) + pose[3:] for p in _camera_axes(loc, hw[:, 0], frame))
    zb = np.maximum(bottom[:, 2], 1e-6)
    zt = np.maximum(top[:, 2], 1e-6)
    ub = k["fx"] * bottom[:, 0] / zb + k["cx"]
    vb = k["fy"] * bottom[:, 1] / zb + k["cy"]
    vt = k["fy"] * top[:, 1] / zt + k["cy"]
    half = k["fx"] * hw[:, 1] / 2 / zb
    return np.c_[ub - half, vt, ub + half, vb], bottom[:, 2]


def _iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    x1, y1 = np.maximum(box[0], boxes[:, 0]), np.maximum(box[1], boxes[:, 1])
    x2, y2 = np.minimum(box[2], boxes[:, 2]), np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    area = lambda b: (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])  # noqa: E731
    return inter / np.maximum(area(box) + area(boxes) - inter, 1e-9)


def _fit_pose(frames: list[_Frame], frame: str) -> tuple[np.ndarray, float] | None:
    """The 3D frame's pose in the camera, fitted (robust least squares) to the rows that carry both a 2D box
    and a 3D location; with the median absolute error in pixels. None with too few rows or no intrinsics."""

    rows = [(b.box, b.location, b.size3d, fr.intrinsics) for fr in frames for b in fr.boxes
            if b.location is not None and b.size3d is not None and fr.intrinsics is not None]
    if frame not in ("camera", "vehicle") or len(rows) < MIN_POSE_ROWS:
        return None
    k = rows[0][3]
    if any(r[3] != k for r in rows):
        return None
    boxes = np.array([r[0] for r in rows], float)
    loc = np.array([r[1] for r in rows], float)
    hw = np.array([r[2] for r in rows], float)

    def residual(p):
        return (_project(p, k, loc, hw, frame)[0] - boxes).ravel()

    fit = least_squares(residual, np.zeros(6), loss="soft_l1", f_scale=5.0)
    return fit.x, float(np.median(np.abs(residual(fit.x))))


def _range_bearing(loc: tuple[float, float, float], frame: str) -> tuple[float, float]:
    x, y, z = loc
    if frame == "camera":
        fwd, left = z, -x
    elif frame == "vehicle":
        fwd, left = x, y
    else:
        return math.nan, math.nan
    return math.hypot(fwd, left), math.atan2(left, fwd)


# ------------------------------------------------------------------------------------ import
PARTIAL = "import.partial.json"
"""Written into ``--out`` before the first frame is copied and removed after ``annotations.json``: marks an
interrupted import (``--resume`` continues it, ``--overwrite`` starts again) and holds what it was made of."""

_DATASET_ENTRIES = ("images", "depth", "masks", MASK_FILE, ANNOTATIONS, PARTIAL)
"""What a dataset folder holds: removed from ``--out`` when an import replaces it (nothing else is touched)."""


def _out_state(out: Path, src: Path, overwrite: bool, resume: bool) -> str:
    """What ``--out`` holds and what to do: ``new``, ``resume``, ``replace`` (an interrupted import or a
    dataset, with ``--overwrite``); anything else is refused before any work."""
    o = Path(os.path.realpath(out))
    if o == src or src in o.parents or o in src.parents:
        raise InputError(f"--out {out} and the source {src} must not contain each other")
    if out.exists() and not out.is_dir():
        raise OutputPathError(f"--out {out} exists and is not a folder")
    entries = {p.name for p in out.iterdir()} if out.is_dir() else set()
    if PARTIAL in entries:
        if resume:
            return "resume"
        if overwrite:
            return "replace"
        raise OutputExistsError(f"--out {out} holds an interrupted import ({PARTIAL}): pass --resume to continue it "
                                "(same source and settings) or --overwrite to start again")
    if ANNOTATIONS in entries:
        if resume:
            raise OutputExistsError(f"{out / ANNOTATIONS} already exists: the import in {out} is complete (--resume "
                                    "continues an interrupted one); pass --overwrite to replace it")
        if not overwrite:
            raise OutputExistsError(f"{out / ANNOTATIONS} already exists; choose another --out folder or pass "
                                    "--overwrite")
        return "replace"
    if entries:
        if overwrite and entries <= {"images", MASK_FILE}:  # what an import writes before annotations.json
            return "replace"
        raise OutputExistsError(f"--out {out} is not empty (and holds no dataset); choose an empty or new folder")
    return "new"


def _clear(out: Path) -> None:
    """Remove what a dataset folder holds (:data:`_DATASET_ENTRIES`) from ``out``; never follows a link."""
    for name in _DATASET_ENTRIES:
        p = out / name
        try:
            if p.is_symlink() or p.is_file():
                p.unlink()
            elif p.is_dir():
                shutil.rmtree(p)
        except OSError as exc:
            raise OutputPathError(f"cannot replace {p}: {exc.strerror or exc}") from None


def _identity(fmt: str, src: Path, frames: list[_Frame], settings: dict[str, Any]) -> dict[str, Any]:
    """What an import is made of: the format, the source, the settings and every source file's size and time
    (a resumed import must continue the same one)."""
    h = hashlib.sha256()
    for fr in frames:
        for p in (fr.image, fr.label):
            if p is not None:
                st = os.stat(p)
                h.update(f"{os.fspath(p)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode("utf-8", "surrogateescape"))
    return {"format": fmt, "source": str(src), **settings, "source_files": h.hexdigest()[:16]}


def _check_resume(out: Path, ident: dict[str, Any]) -> None:
    try:
        old = json.loads(read_text(out / PARTIAL, root=out)).get("identity")
    except (json.JSONDecodeError, AttributeError, FileFormatError):
        old = None
    if not isinstance(old, dict):
        raise OutputExistsError(f"{out / PARTIAL} cannot be read: the interrupted import cannot be checked; "
                                "pass --overwrite to start again")
    diff = [k for k in sorted(set(old) | set(ident)) if old.get(k) != ident.get(k)]
    if diff:
        what = ", ".join(f"{k} {old.get(k)!r} -> {ident.get(k)!r}" if k != "source_files"
                         else "the source files changed since" for k in diff)
        raise InputError(f"--resume: the interrupted import in {out} was made with other settings ({what}); "
                         "rerun it with the same ones, or pass --overwrite to start again")


def import_dataset(fmt: str, src: str | os.PathLike, out: str | os.PathLike, *,
                   classes: str | Mapping[str, str] | None = None, condition: str | None = None,
                   severity: int | None = None, intrinsics: Any = None, detector: Any = None,
                   mask: str | os.PathLike | None = None, annotations: str | os.PathLike | None = None,
                   location_frame: str = "auto", project_3d: bool = True, overwrite: bool = False,
                   resume: bool = False, progress: bool = False) -> dict[str, Any]:
    """Import ``src`` (format ``fmt``) into the COCO folder ``out``; returns a summary dict (see module doc).

    ``detector``: whose input scale the too-small rule is stated at (an object with ``input_size`` and
    ``resize``, e.g. a loaded detector; default: the shipped detector's 512x288 letterbox).
    ``mask``: an ignore-mask PNG stored with the dataset. ``project_3d``: KITTI rows with only a 3D box
    become ignore regions where the fitted camera sees them (False: they are only left out).
    ``resume``: continue an interrupted import into ``out`` (same source and settings, else an error);
    ``overwrite``: replace a dataset or an interrupted import in ``out``. Another import writing into
    ``out`` at the same time is refused (:class:`OutputExistsError`).
    """
    if fmt not in FORMATS:
        raise InputError(f"unknown dataset format {fmt!r}; expected one of {', '.join(FORMATS)}")
    if resume and overwrite:
        raise InputError("--resume continues an interrupted import, --overwrite starts again: pass one of them")
    given_src, out = Path(src), Path(out)
    if not given_src.is_dir():
        raise MissingInputError(f"source folder {given_src} " + ("is not a folder" if given_src.exists() else "not found"))
    src = Path(os.path.realpath(given_src))
    cmap = parse_class_map(classes)
    cond, sev = _condition(condition, severity)
    given_k = parse_intrinsics(intrinsics)
    if location_frame not in ("auto", "camera", "vehicle", "none"):
        raise InputError(f"location frame must be auto, camera, vehicle or none, got {location_frame!r}")
    if mask is not None and not Path(mask).is_file():
        raise MissingInputError(f"--mask {mask} not found")
    _out_state(out, src, overwrite, resume)  # refuse early, before anything is made
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(f"cannot make --out {out}: {exc.strerror or exc}") from None
    try:
        with exclusive_folder(out, busy=f"another import is writing into {out}; wait for it to finish or choose "
                                        "another --out folder"):
            state = _out_state(out, src, overwrite, resume)  # again, now that no other writer can change it
            return _import(fmt, src, out, state, cmap=cmap, cond=cond, sev=sev, given_k=given_k, detector=detector,
                           mask=mask, annotations=annotations, location_frame=location_frame,
                           project_3d=project_3d, progress=progress)
    except BaseException:
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()  # only when nothing was written
        raise


def _import(fmt: str, src: Path, out: Path, state: str, *, cmap: dict[str, str], cond: str | None,
            sev: int | None, given_k: dict[str, float] | None, detector: Any, mask: Any, annotations: Any,
            location_frame: str, project_3d: bool, progress: bool) -> dict[str, Any]:
    # 1. read and validate everything before writing anything
    if fmt == "kitti":
        read = _read_kitti(src)
    elif fmt == "yolo":
        read = _read_yolo(src)
    elif fmt == "supervisely":
        read = _read_supervisely(src)
    else:
        read = _read_coco(src, Path(annotations) if annotations is not None else None)
    frames, stats = read.frames, read.stats
    if not frames:
        raise FileFormatError(f"{src}: no frames to import")
    for fr in tqdm(frames, desc="check", unit="frame", disable=not progress):
        if fr.size == (0, 0):
            fr.size = _image_size(fr, src)
        if fr.stated_size is not None and fr.stated_size != fr.size:
            raise FileFormatError(f"{src / fr.source_file} is {fr.size[0]}x{fr.size[1]} but its labels state "
                                  f"{fr.stated_size[0]}x{fr.stated_size[1]}")
    sizes = Counter(fr.size for fr in frames)
    size = frames[0].size if len(sizes) == 1 else None
    if given_k is not None and size is None:
        raise InputError(f"--intrinsics are of one camera at one size, but the frames have {len(sizes)} sizes "
                         f"({_sizes_text(sizes)}); import each camera into its own folder to give its intrinsics")
    if mask is not None and size is None:
        raise InputError(f"--mask: a dataset-wide ignore mask needs frames of one size, but they have "
                         f"{len(sizes)} ({_sizes_text(sizes)}); set per-frame masks later with "
                         "weather-gym dataset mask DIR --set MASK --frame FILE")
    unmapped = sorted({b.cls for fr in frames for b in fr.boxes if b.cls not in cmap})
    if unmapped and "*" not in cmap:
        where = next(b.where for fr in frames for b in fr.boxes if b.cls == unmapped[0])
        raise FileFormatError(f"{where}: class {unmapped[0]!r} is not in the class map "
                         f"({', '.join(f'{k}={v}' for k, v in cmap.items())}); classes found but not mapped: "
                         f"{', '.join(unmapped)}. Map each to a cone class, or to 'ignore' to make its boxes ignore "
                         f"regions (e.g. {unmapped[0]}=ignore, or *=ignore for every unmapped class)")
    rels = Counter(fr.rel for fr in frames)
    if max(rels.values()) > 1:
        dup = next(r for r, n in rels.items() if n > 1)
        raise FileFormatError(f"{src}: two frames would both be stored as images/{dup}")
    for fr in frames:
        for b in fr.boxes:
            x1, y1, x2, y2 = b.box
            if x1 < -1 or y1 < -1 or x2 > fr.size[0] + 1 or y2 > fr.size[1] + 1:
                raise FileFormatError(f"{b.where}: box ({x1:g}, {y1:g}, {x2:g}, {y2:g}) lies outside the "
                                 f"{fr.size[0]}x{fr.size[1]} image {src / fr.source_file}")
            b.box = (max(x1, 0.0), max(y1, 0.0), min(x2, float(fr.size[0])), min(y2, float(fr.size[1])))
        k = given_k or fr.intrinsics
        if k is not None:
            try:
                CameraConfig.from_intrinsics(fr.size[0], fr.size[1], **k)
            except ValueError as exc:
                raise FileFormatError(f"{src / fr.source_file}: {exc}") from None
            fr.intrinsics = k
    loc_frame, loc_why = _location_frame(frames, location_frame) if fmt == "kitti" else ("none", "none")
    projected = _project_only3d(frames, loc_frame) if fmt == "kitti" and project_3d else None
    rules = {s: SmallRule.for_image(s, detector) for s in sizes}
    mask_arr = read_mask(mask, size) if mask is not None else None
    settings = {"annotations": None if annotations is None else os.path.realpath(annotations), "classes": cmap,
                "condition": cond, "severity": sev, "intrinsics": given_k, "location_frame": location_frame,
                "project_3d": project_3d, "too_small": {f"{w}x{h}": r.min_height_px for (w, h), r in rules.items()},
                "mask": None if mask is None else file_id(mask)}
    ident = _identity(fmt, src, frames, settings)
    if state == "resume":
        _check_resume(out, ident)

    # 2. write: the marker, the frames byte for byte, annotations.json, then the marker goes
    atomic_write_json(out / PARTIAL, {"identity": ident}, overwrite=state != "new")
    if state == "replace":
        _clear_but_marker(out)
    images, anns = [], []
    per_class: Counter = Counter()
    ignored: Counter = Counter()
    n_small = n_kept = 0
    for i, fr in enumerate(tqdm(frames, desc="import", unit="frame", disable=not progress)):
        dest = resolve_inside(out / "images", fr.rel, what=f"{src / fr.source_file}")
        if not (state == "resume" and dest.is_file() and dest.stat().st_size == fr.image.stat().st_size):
            atomic_write(dest, read_bytes(fr.image, root=src), overwrite=state == "resume")  # byte for byte
        else:
            n_kept += 1
        rec: dict[str, Any] = {"id": i, "file_name": f"images/{fr.rel}", "width": fr.size[0],
                               "height": fr.size[1], "source_file": fr.source_file}
        if fr.intrinsics is not None:
            rec["intrinsics"] = {k: float(v) for k, v in fr.intrinsics.items()}
            rec["camera"] = CameraConfig.from_intrinsics(fr.size[0], fr.size[1], **fr.intrinsics).to_dict()
        if cond is not None:
            rec["condition"], rec["severity"] = cond, sev
        images.append(rec)
        rule = rules[fr.size]
        for b in fr.boxes:
            target = cmap.get(b.cls, cmap.get("*"))
            x1, y1, x2, y2 = b.box
            ign = target == IGNORE or b.crowd
            cls = CONE_CLASSES.index(target) if target != IGNORE else 0
            small = (y2 - y1) < rule.min_height_px
            a = {"id": len(anns) + 1, "image_id": i, "category_id": cls + 1, "bbox": [x1, y1, x2 - x1, y2 - y1],
                 "area": (x2 - x1) * (y2 - y1), "iscrowd": int(ign or small), "source_class": b.cls}
            if ign:
                a["ignore"] = f"unmapped class {b.cls}" if target == IGNORE else f"crowd of {b.cls}"
                a["any_class"] = target == IGNORE
                ignored[b.cls] += 1
            elif small:
                n_small += 1
            else:
                per_class[target] += 1
            rng, bear = (_range_bearing(b.location, loc_frame) if b.location is not None else (b.range, b.bearing))
            if math.isfinite(rng):
                a["range"], a["bearing"] = float(rng), float(bear)
            anns.append(a)
        for cls, box in (projected or {}).get(i, []):
            x1, y1, x2, y2 = box
            anns.append({"id": len(anns) + 1, "image_id": i, "category_id": 1, "bbox": [x1, y1, x2 - x1, y2 - y1],
                         "area": (x2 - x1) * (y2 - y1), "iscrowd": 1, "source_class": f"{cls} (3D only, projected)",
                         "ignore": f"3D only {cls} (projected)", "any_class": True})
    if size is not None:
        too_small = rules[size].to_dict()
    else:
        one = next(iter(rules.values()))
        iw, ih = one.input_size
        too_small = {"min_input_px": one.min_input_px, "input_size": list(one.input_size), "resize": one.resize,
                     "per_size": {f"{w}x{h}": r.min_height_px for (w, h), r in sorted(rules.items())},
                     "rule": (f"box height < {one.min_input_px:.2g} px at the detector's {iw}x{ih} input ({one.resize}): "
                              + ", ".join(f"{r.min_height_px:.3g} px in {w}x{h}" for (w, h), r in sorted(rules.items())))}
    info: dict[str, Any] = {
        "description": f"imported from {fmt} by weather-gym dataset import", "origin": "import", "format": fmt,
        "layout": read.layout, "source": str(src), "class_map": cmap, "too_small": too_small,
        "size": None if size is None else list(size), "sizes": {f"{w}x{h}": n for (w, h), n in sorted(sizes.items())},
        "rows_left_out": dict(stats), "ignore_regions": dict(ignored), "labels_without_image": read.unmatched,
        "projected_3d": None if projected is None else projected["summary"],
        "location_frame": loc_why if fmt == "kitti" else None,
        "intrinsics": "given" if given_k else ("calibration files" if any(f.intrinsics for f in frames) else "unknown"),
    }
    if size is not None:
        info["min_box_height_px"] = rules[size].min_height_px
    if cond is not None:
        info["condition"], info["severity"] = cond, sev
    if mask_arr is not None:
        write_mask(out / MASK_FILE, mask_arr, overwrite=state != "new")
        info["ignore_mask"] = MASK_FILE
    atomic_write_json(out / ANNOTATIONS, {"info": info, "images": images, "annotations": anns,
                                          "categories": CATEGORIES}, overwrite=state != "new")
    (out / PARTIAL).unlink()
    rule_text = rules[size].describe() if size is not None else too_small["rule"]
    return {"out": str(out), "frames": len(images), "size": None if size is None else list(size),
            "sizes": info["sizes"], "cones": dict(per_class), "too_small": n_small, "ignore_regions": dict(ignored),
            "rows_left_out": dict(stats), "rule": rule_text, "location_frame": loc_why, "intrinsics": info["intrinsics"],
            "condition": cond, "severity": sev, "ignore_mask": info.get("ignore_mask"),
            "projected_3d": info["projected_3d"], "labels_without_image": read.unmatched, "layout": read.layout,
            "resumed": n_kept if state == "resume" else None}


def _clear_but_marker(out: Path) -> None:
    """Remove the dataset ``out`` held (its frames, masks, annotations), keeping the new import's marker."""
    marker = (out / PARTIAL).read_bytes()
    _clear(out)
    atomic_write(out / PARTIAL, marker)


def _sizes_text(sizes: Mapping[tuple[int, int], int]) -> str:
    return ", ".join(f"{w}x{h} ({n})" for (w, h), n in sorted(sizes.items()))


def _project_only3d(frames: list[_Frame], loc_frame: str) -> dict | None:
    """Ignore regions for the 3D-only rows: ``{frame index: [(class, xyxy)], "summary": str}``, or None when
    the camera pose cannot be fitted. Each projected box is grown by the fit's median error plus a quarter
    of its size on every side (a region, not a label), clipped to the frame; cones behind the camera, out
    of the frame or nearer than 0.5 m are skipped, and so are rows that repeat a cone with a 2D box (the
    projection overlaps one at IoU >= 0.3)."""
    if not any(fr.only3d for fr in frames):
        return None
    fitted = _fit_pose(frames, loc_frame)
    if fitted is None:
        return None
    pose, err = fitted
    out: dict[Any, Any] = {}
    n = n_out = n_dup = 0
    for i, fr in enumerate(frames):
        if not fr.only3d or fr.intrinsics is None:
            continue
        loc = np.array([r[2] for r in fr.only3d], float)
        hw = np.array([r[1][:2] for r in fr.only3d], float)
        boxes, fwd = _project(pose, fr.intrinsics, loc, hw, loc_frame)
        labelled = np.array([b.box for b in fr.boxes], float).reshape(-1, 4)
        w, h = fr.size
        for (cls, *_), b, z in zip(fr.only3d, boxes, fwd, strict=True):
            if len(labelled) and _iou(b, labelled).max() >= 0.3:
                n_dup += 1
                continue
            grow = np.array([-1, -1, 1, 1]) * (err + 0.25 * np.array([b[2] - b[0], b[3] - b[1]] * 2))
            g = b + grow
            if z < 0.5 or g[2] <= 0 or g[3] <= 0 or g[0] >= w or g[1] >= h:
                n_out += 1
                continue
            g = (max(0.0, g[0]), max(0.0, g[1]), min(float(w), g[2]), min(float(h), g[3]))
            out.setdefault(i, []).append((cls, tuple(float(v) for v in g)))
            n += 1
    out["summary"] = (f"{n} 3D-only cones in view projected into ignore regions ({n_out} behind or out of the frame, "
                      f"{n_dup} repeating a cone with a 2D box); "
                      f"camera pose fitted to the rows with both boxes, median error {err:.1f} px")
    return out
