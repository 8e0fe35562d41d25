"""Import labelled camera recordings (KITTI, YOLO txt, COCO) into the project's COCO layout.

``weather-gym dataset import {kitti,yolo,coco} SRC --out DIR`` (:func:`import_dataset`) reads a folder
of frames and labels, validates all of it first, then copies the frames (byte for byte) into
``DIR/images/`` and writes ``DIR/annotations.json``; nothing outside ``DIR`` is written.

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
  without cones, a missing one an error.
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

import json
import math
import os
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from weather_gym._io import atomic_write, atomic_write_json, resolve_inside
from weather_gym.camera import CameraConfig
from weather_gym.cone_spec import CONE_CLASSES
from weather_gym.datasets.coco import ANNOTATIONS
from weather_gym.datasets.masks import MASK_FILE, read_mask, write_mask
from weather_gym.errors import (
    FileFormatError,
    InputError,
    MissingInputError,
    OutputExistsError,
    OutputPathError,
)
from weather_gym.perception.labels import CATEGORIES, DEFAULT_CLASSES, IGNORE, SmallRule, parse_class_map
from weather_gym.weather.presets import CONDITIONS, canonical_condition

__all__ = ["FORMATS", "DEFAULT_CLASSES", "IGNORE", "parse_class_map", "parse_intrinsics", "import_dataset"]

FORMATS = ("kitti", "yolo", "coco")
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
    if len(nums) != 4 or not all(math.isfinite(v) for v in nums) or nums[0] <= 0 or nums[1] <= 0:
        raise InputError(f"intrinsics {spec!r}: expected fx,fy,cx,cy in pixels at the image size (fx, fy > 0), "
                         "e.g. 900.9,900.1,506.4,358.0")
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
    image: Path
    rel: str
    boxes: list[_Box] = field(default_factory=list)
    only3d: list[tuple[str, tuple[float, float, float], tuple[float, float, float], str]] = field(default_factory=list)
    intrinsics: dict[str, float] | None = None
    size: tuple[int, int] = (0, 0)


def _find_dir(src: Path, names: Sequence[str], what: str, required: bool = True) -> Path | None:
    for n in names:
        if (src / n).is_dir():
            return src / n
    if required:
        raise MissingInputError(f"{src}: no {what} folder (looked for {', '.join(n + '/' for n in names)})")
    return None


def _images_under(folder: Path) -> list[Path]:
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in IMAGE_EXTS)
    if not files:
        raise MissingInputError(f"{folder}: no images ({', '.join(IMAGE_EXTS)})")
    return files


def _label_for(image: Path, images: Path, labels: Path) -> Path:
    return (labels / image.relative_to(images)).with_suffix(".txt")


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


def _labelled(images: Path, labels: Path, fmt: str) -> Iterator[tuple[Path, Path, _Frame]]:
    """Each image under ``images`` with its label file (mirrored under ``labels``, ``.txt``) and a new frame."""
    for img in _images_under(images):
        lab = _label_for(img, images, labels)
        if not lab.is_file():
            raise MissingInputError(f"{img}: its {fmt} label file {lab} is missing (every image needs one; an "
                                    "empty file means no cones)")
        yield img, lab, _Frame(img, str(img.relative_to(images)))


def _read_kitti(src: Path) -> tuple[list[_Frame], Counter]:
    images = _find_dir(src, _KITTI_DIRS["images"], "images")
    labels = _find_dir(src, _KITTI_DIRS["labels"], "labels")
    calib = _find_dir(src, _KITTI_DIRS["calib"], "calib", required=False)
    stats: Counter = Counter()
    frames = []
    for img, lab, fr in _labelled(images, labels, "KITTI"):
        for n, line in enumerate(lab.read_text().splitlines(), 1):
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
                stats["rows without a 2D box (3D only): left out"] += 1
                if any(v[10:13]) and all(d > 0 for d in v[7:9]):  # (h, w, l), location: projected later
                    fr.only3d.append((parts[0], tuple(v[7:10]), tuple(v[10:13]), where))
                continue
            loc = tuple(v[10:13]) if any(v[7:13]) else None
            size3d = (v[7], v[8]) if v[7] > 0 and v[8] > 0 else None
            fr.boxes.append(_Box(parts[0], _check_box(x1, y1, x2, y2, where), where, location=loc, size3d=size3d))
        if calib is not None:
            fr.intrinsics = _kitti_calib((calib / img.relative_to(images)).with_suffix(".txt"))
        frames.append(fr)
    return frames, stats


def _kitti_calib(path: Path) -> dict[str, float] | None:
    if not path.is_file():
        return None
    for n, line in enumerate(path.read_text().splitlines(), 1):
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
        if (src / name).is_file():
            return [ln.strip() for ln in (src / name).read_text().splitlines() if ln.strip()]
    for name in ("data.yaml", "dataset.yaml"):
        if (src / name).is_file():
            return _yaml_names(src / name)
    return None


def _yaml_names(path: Path) -> list[str]:
    """``names`` of a YOLO data.yaml: a list (inline or block) or an index -> name mapping."""
    try:
        import yaml

        data = yaml.safe_load(path.read_text())
        names = data.get("names") if isinstance(data, dict) else None
    except ImportError:  # a minimal reader of the two usual forms
        names, block = None, None
        for line in path.read_text().splitlines():
            s = line.split("#", 1)[0].rstrip()
            if s.startswith("names:"):
                rest = s[6:].strip()
                if rest.startswith("["):
                    names = [t.strip().strip("'\"") for t in rest.strip("[]").split(",") if t.strip()]
                    break
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
        if names is None:
            names = block
    except Exception as exc:
        raise FileFormatError(f"{path} is not valid YAML: {exc}") from None
    if isinstance(names, dict):
        names = [str(names[k]) for k in sorted(names, key=int)]
    if not isinstance(names, list) or not names:
        raise FileFormatError(f"{path}: expected a 'names' list (or index: name mapping) of the classes")
    return [str(n) for n in names]


def _read_yolo(src: Path) -> tuple[list[_Frame], Counter]:
    images = _find_dir(src, ("images",), "images")
    labels = _find_dir(src, ("labels",), "labels")
    names = _yolo_names(src)
    stats: Counter = Counter()
    frames = []
    for img, lab, fr in _labelled(images, labels, "YOLO"):
        fr.size = _image_size(img)
        w, h = fr.size
        for n, line in enumerate(lab.read_text().splitlines(), 1):
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
        frames.append(fr)
    return frames, stats


def _read_coco(src: Path, annotations: Path | None) -> tuple[list[_Frame], Counter]:
    if annotations is None:
        cands = sorted(src.glob("*.json"))
        if len(cands) != 1:
            raise MissingInputError(f"{src}: expected exactly one COCO *.json file, found "
                                    f"{len(cands)} ({', '.join(p.name for p in cands) or 'none'}); pass --annotations")
        annotations = cands[0]
    try:
        data = json.loads(Path(annotations).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"{annotations} is not a readable COCO JSON file: {exc}") from None
    for key in ("images", "annotations", "categories"):
        if not isinstance(data, dict) or not isinstance(data.get(key), list):
            raise FileFormatError(f"{annotations}: missing or invalid key {key!r} (expected a list)")
    cats = {}
    for c in data["categories"]:
        if not isinstance(c, dict) or "id" not in c or "name" not in c:
            raise FileFormatError(f"{annotations}: category {c!r} needs an id and a name")
        cats[c["id"]] = str(c["name"])
    base = Path(annotations).parent
    frames, by_id = [], {}
    for im in data["images"]:
        if not isinstance(im, dict) or "id" not in im or "file_name" not in im:
            raise FileFormatError(f"{annotations}: image record {im!r} needs an id and a file_name")
        rel = Path(str(im["file_name"]))
        what = f"{annotations}: image {im['id']} 'file_name'"
        cands = (resolve_inside(base, rel, what=what), resolve_inside(base / "images", rel, what=what))
        path = next((p for p in cands if p.is_file()), None)
        if path is None:
            raise MissingInputError(f"{annotations}: image {im['id']} file {im['file_name']} not found under {base} "
                                    f"or {base / 'images'}")
        fr = _Frame(path, str(rel))
        frames.append(fr)
        by_id[im["id"]] = fr
    for a in data["annotations"]:
        where = f"{annotations}: annotation {a.get('id') if isinstance(a, dict) else a!r}"
        if not isinstance(a, dict) or a.get("image_id") not in by_id:
            raise FileFormatError(f"{where} refers to an unknown image_id")
        if a.get("category_id") not in cats:
            raise FileFormatError(f"{where} has an unknown category_id {a.get('category_id')!r}")
        b = a.get("bbox")
        if not isinstance(b, list) or len(b) != 4:
            raise FileFormatError(f"{where}: bbox {b!r} is not [x, y, w, h]")
        x, y, w, h = _floats([str(v) for v in b], where, "bbox")
        box = _Box(cats[a["category_id"]], _check_box(x, y, x + w, y + h, where), where, crowd=bool(a.get("iscrowd")))
        box.range = float(a["range"]) if isinstance(a.get("range"), int | float) else math.nan
        by_id[a["image_id"]].boxes.append(box)
    return frames, Counter()


def _image_size(path: Path) -> tuple[int, int]:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise FileFormatError(f"image file {path} could not be decoded as an image")
    if img.ndim == 2 or img.shape[2] not in (3, 4):
        raise FileFormatError(f"image file {path} has {1 if img.ndim == 2 else img.shape[2]} channel(s); expected colour "
                         "(RGB) frames")
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
def _prepare_out(out: Path, src: Path, overwrite: bool) -> None:
    o, s = out.resolve(), src.resolve()
    if o == s or s in o.parents or o in s.parents:
        raise InputError(f"--out {out} and the source {src} must not contain each other")
    if (out / ANNOTATIONS).exists() and not overwrite:
        raise OutputExistsError(f"{out / ANNOTATIONS} already exists; choose another --out folder or pass --overwrite")
    if out.exists() and not out.is_dir():
        raise OutputPathError(f"--out {out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / ANNOTATIONS).exists():
        raise OutputExistsError(f"--out {out} is not empty (and holds no dataset); choose an empty or new folder")


def import_dataset(fmt: str, src: str | os.PathLike, out: str | os.PathLike, *,
                   classes: str | Mapping[str, str] | None = None, condition: str | None = None,
                   severity: int | None = None, intrinsics: Any = None, detector: Any = None,
                   mask: str | os.PathLike | None = None, annotations: str | os.PathLike | None = None,
                   location_frame: str = "auto", project_3d: bool = True, overwrite: bool = False,
                   progress: bool = False) -> dict[str, Any]:
    """Import ``src`` (format ``fmt``) into the COCO folder ``out``; returns a summary dict (see module doc).

    ``detector``: whose input scale the too-small rule is stated at (an object with ``input_size`` and
    ``resize``, e.g. a loaded detector; default: the shipped detector's 512x288 letterbox).
    ``mask``: an ignore-mask PNG stored with the dataset. ``project_3d``: KITTI rows with only a 3D box
    become ignore regions where the fitted camera sees them (False: they are only left out).
    """


    if fmt not in FORMATS:
        raise InputError(f"unknown dataset format {fmt!r}; expected one of {', '.join(FORMATS)}")
    src, out = Path(src), Path(out)
    if not src.is_dir():
        raise MissingInputError(f"source folder {src} not found")
    cmap = parse_class_map(classes)
    cond, sev = _condition(condition, severity)
    given_k = parse_intrinsics(intrinsics)
    _prepare_out(out, src, overwrite)

    # 1. read and validate everything before writing anything
    if fmt == "kitti":
        frames, stats = _read_kitti(src)
    elif fmt == "yolo":
        frames, stats = _read_yolo(src)
    else:
        frames, stats = _read_coco(src, Path(annotations) if annotations is not None else None)
    if not frames:
        raise FileFormatError(f"{src}: no frames to import")
    for fr in tqdm(frames, desc="check", unit="frame", disable=not progress):
        if fr.size == (0, 0):
            fr.size = _image_size(fr.image)
    size = frames[0].size
    for fr in frames:
        if fr.size != size:
            raise FileFormatError(f"{fr.image} is {fr.size[0]}x{fr.size[1]} but {frames[0].image} is {size[0]}x{size[1]}: "
                             "one dataset holds frames of one camera and size (import each size into its own folder)")
    unmapped = sorted({b.cls for fr in frames for b in fr.boxes if b.cls not in cmap})
    if unmapped and "*" not in cmap:
        where = next(b.where for fr in frames for b in fr.boxes if b.cls == unmapped[0])
        raise FileFormatError(f"{where}: class {unmapped[0]!r} is not in the class map "
                         f"({', '.join(f'{k}={v}' for k, v in cmap.items())}); classes found but not mapped: "
                         f"{', '.join(unmapped)}. Map each to a cone class, or to 'ignore' to make its boxes ignore "
                         f"regions (e.g. {unmapped[0]}=ignore, or *=ignore for every unmapped class)")
    for fr in frames:
        for b in fr.boxes:
            x1, y1, x2, y2 = b.box
            if x1 < -1 or y1 < -1 or x2 > fr.size[0] + 1 or y2 > fr.size[1] + 1:
                raise FileFormatError(f"{b.where}: box ({x1:g}, {y1:g}, {x2:g}, {y2:g}) lies outside the "
                                 f"{fr.size[0]}x{fr.size[1]} image {fr.image}")
            b.box = (max(x1, 0.0), max(y1, 0.0), min(x2, float(fr.size[0])), min(y2, float(fr.size[1])))
        k = given_k or fr.intrinsics
        if k is not None:
            try:
                CameraConfig.from_intrinsics(fr.size[0], fr.size[1], **k)
            except ValueError as exc:
                raise FileFormatError(f"{fr.image}: {exc}") from None
            fr.intrinsics = k
    loc_frame, loc_why = _location_frame(frames, location_frame) if fmt == "kitti" else ("none", "none")
    projected = _project_only3d(frames, loc_frame) if fmt == "kitti" and project_3d else None
    rule = SmallRule.for_image(size, detector)
    mask_arr = read_mask(mask, size) if mask is not None else None

    # 2. write: frames copied byte for byte, then annotations.json last
    images, anns = [], []
    per_class: Counter = Counter()
    ignored: Counter = Counter()
    n_small = 0
    for i, fr in enumerate(tqdm(frames, desc="import", unit="frame", disable=not progress)):
        dest = resolve_inside(out / "images", fr.rel, what=f"{fr.image}")
        atomic_write(dest, fr.image.read_bytes(), overwrite=overwrite)  # byte for byte
        rec: dict[str, Any] = {"id": i, "file_name": f"images/{Path(fr.rel).as_posix()}", "width": fr.size[0],
                               "height": fr.size[1], "source_file": str(fr.image.relative_to(src).as_posix())}
        if fr.intrinsics is not None:
            rec["intrinsics"] = {k: float(v) for k, v in fr.intrinsics.items()}
            rec["camera"] = CameraConfig.from_intrinsics(fr.size[0], fr.size[1], **fr.intrinsics).to_dict()
        if cond is not None:
            rec["condition"], rec["severity"] = cond, sev
        images.append(rec)
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
    info: dict[str, Any] = {
        "description": f"imported from {fmt} by weather-gym dataset import", "origin": "import", "format": fmt,
        "source": str(src.resolve()), "class_map": cmap, "too_small": rule.to_dict(),
        "min_box_height_px": rule.min_height_px, "size": list(size),
        "rows_left_out": dict(stats), "ignore_regions": dict(ignored),
        "projected_3d": None if projected is None else projected["summary"],
        "location_frame": loc_why if fmt == "kitti" else None,
        "intrinsics": "given" if given_k else ("calibration files" if any(f.intrinsics for f in frames) else "unknown"),
    }
    if cond is not None:
        info["condition"], info["severity"] = cond, sev
    if mask_arr is not None:
        write_mask(out / MASK_FILE, mask_arr, overwrite=overwrite)
        info["ignore_mask"] = MASK_FILE
    atomic_write_json(out / ANNOTATIONS, {"info": info, "images": images, "annotations": anns,
                                          "categories": CATEGORIES}, overwrite=overwrite)
    return {"out": str(out), "frames": len(images), "size": list(size), "cones": dict(per_class),
            "too_small": n_small, "ignore_regions": dict(ignored), "rows_left_out": dict(stats),
            "rule": rule.describe(), "location_frame": loc_why, "intrinsics": info["intrinsics"],
            "condition": cond, "severity": sev, "ignore_mask": info.get("ignore_mask"),
            "projected_3d": info["projected_3d"]}


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
