"""The source formats an import reads (KITTI, YOLO txt, COCO, Supervisely/FSOCO): one reader each,
picked by :func:`read_source`. Each reads and validates every label before anything is written (see
:mod:`weather_gym.lab.datasets.importers` for the layouts).

Example:
    >>> import tempfile
    >>> src = Path(tempfile.mkdtemp())
    >>> read_source("yolo", src, None)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.MissingInputError: ...: no images (.png, .jpg, .jpeg, .bmp): expected images/ + labels/, ...
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter
from pathlib import Path
from typing import Any

from weather_gym.core._confine import read_text, walk_files
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError, OutsideRootError
from weather_gym.lab.datasets.import_frames import (
    IMAGE_EXTS,
    LabelBox,
    SourceFrame,
    SourceRead,
    check_box,
    check_one_image_per_label,
    find_dir,
    image_size,
    images_under,
    is_image,
    labelled_frames,
    parse_floats,
    rel_path,
    source_frame,
)

_KITTI_DIRS = {"images": ("images", "image_2", "image"), "labels": ("labels", "label_2", "label"), "calib": ("calib",)}


def read_source(fmt: str, src: Path, annotations: Path | None) -> SourceRead:
    """Read the source folder ``src`` of format ``fmt`` (``annotations``: COCO's JSON file, if named)."""
    if fmt == "kitti":
        return _read_kitti(src)
    if fmt == "yolo":
        return _read_yolo(src)
    if fmt == "supervisely":
        return _read_supervisely(src)
    if fmt == "coco":
        return _read_coco(src, annotations)
    raise InputError(f"unknown dataset format {fmt!r}; expected one of kitti, yolo, coco, supervisely")


def _read_kitti(src: Path) -> SourceRead:
    images = find_dir(src, _KITTI_DIRS["images"], "images")
    labels = find_dir(src, _KITTI_DIRS["labels"], "labels")
    calib = find_dir(src, _KITTI_DIRS["calib"], "calib", required=False)
    assert images is not None and labels is not None  # required: find_dir raised otherwise
    res = SourceRead([], layout=f"{images.name}/ + {labels.name}/")
    for lab, fr in labelled_frames(images, labels, src, "KITTI", unmatched=res.unmatched):
        for n, line in enumerate(read_text(lab, root=src).splitlines(), 1):
            parts = line.split()
            if not parts:
                continue
            where = f"{lab}:{n}"
            if len(parts) not in (15, 16):
                raise FileFormatError(f"{where}: a KITTI row has 15 values (type truncated occluded alpha x1 y1 x2 y2 "
                                 f"h w l x y z rotation_y) or 16 (with score), got {len(parts)}")
            v = parse_floats(parts[1:15], where, "the KITTI columns")
            x1, y1, x2, y2 = v[3:7]
            if x1 == y1 == x2 == y2 == 0.0:
                res.stats["rows without a 2D box (3D only): left out"] += 1
                if any(v[10:13]) and all(d > 0 for d in v[7:9]):  # (h, w, l), location: projected later
                    fr.only3d.append((parts[0], (v[7], v[8], v[9]), (v[10], v[11], v[12]), where))
                continue
            loc = (v[10], v[11], v[12]) if any(v[7:13]) else None
            size3d = (v[7], v[8]) if v[7] > 0 and v[8] > 0 else None
            fr.boxes.append(LabelBox(parts[0], check_box(x1, y1, x2, y2, where), where, location=loc, size3d=size3d))
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
            v = parse_floats(rest.split(), f"{path}:{n}", key.strip())
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
    names = None
    block: list[str] | None = None
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


def _yolo_rows(lab: Path, src: Path, fr: SourceFrame, names: list[str] | None) -> None:
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
        cx, cy, bw, bh = parse_floats(parts[1:], where, "cx cy w h")
        if not all(-0.01 <= v <= 1.01 for v in (cx, cy, bw, bh)):
            raise FileFormatError(f"{where}: cx cy w h must be normalised to [0, 1], got {' '.join(parts[1:])}")
        if names is not None and not 0 <= idx < len(names):
            raise FileFormatError(f"{where}: class index {idx} is outside the {len(names)} class names of {src}")
        cls = names[idx] if names is not None else str(idx)
        box = ((cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h)
        fr.boxes.append(LabelBox(cls, check_box(*box, where), where))


_NOT_LABELS = frozenset({"classes.txt", "train.txt", "val.txt", "valid.txt", "test.txt", "readme.txt", "license.txt"})
"""``.txt`` files of a darknet folder that are not label files."""


def _read_yolo(src: Path) -> SourceRead:
    """``images/`` + ``labels/`` (mirrored), or the darknet layout: ``img.jpg`` and ``img.txt`` side by side."""
    names = _yolo_names(src)
    if (src / "images").is_dir() and (src / "labels").is_dir():
        res = SourceRead([], layout="images/ + labels/")
        pairs = list(labelled_frames(src / "images", src / "labels", src, "YOLO", unmatched=res.unmatched))
    else:
        res = SourceRead([], layout="labels beside the images (darknet)")
        files = walk_files(src, src)
        imgs = [p for p in files if is_image(p)]
        if not imgs:
            raise MissingInputError(f"{src}: no images ({', '.join(IMAGE_EXTS)}): expected images/ + labels/, or "
                                    "images with their .txt label files beside them (darknet)")
        stems = {p.with_suffix("") for p in imgs}
        res.unmatched += [rel_path(p, src) for p in files if p.suffix == ".txt" and p.with_suffix("") not in stems
                          and p.name.lower() not in _NOT_LABELS]
        pairs = []
        check_one_image_per_label(imgs, [img.with_suffix(".txt") for img in imgs])
        for img in imgs:
            lab = img.with_suffix(".txt")
            if not lab.is_file() and not lab.is_symlink():
                raise MissingInputError(f"{img}: its YOLO label file {lab} is missing (in the darknet layout every "
                                        "image needs a .txt beside it; an empty file means no cones)")
            fr = source_frame(img, rel_path(img, src), src)
            fr.label = lab
            pairs.append((lab, fr))
    for lab, fr in pairs:
        fr.size = image_size(fr, src)
        _yolo_rows(lab, src, fr, names)
        res.frames.append(fr)
    return res


def _json(path: Path, src: Path | None, what: str) -> Any:
    text = read_text(path, root=src)
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise FileFormatError(f"{path} is not a valid {what} JSON file: {exc}") from None


def _read_coco(src: Path, annotations: Path | None) -> SourceRead:  # noqa: C901 (COCO validation, key by key)
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
            rel = rel_path(path, Path(os.path.normpath(src)))
        if im["id"] in by_id:
            raise FileFormatError(f"{annotations}: duplicate image id {im['id']!r}")
        if rel in seen:
            raise FileFormatError(f"{annotations}: image {im['id']}: file {rel} is listed twice")
        seen.add(rel)
        fr = source_frame(path, Path(rel).as_posix(), src)
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
        x, y, w, h = parse_floats([str(v) for v in b], where, "bbox")
        box = LabelBox(cats[a["category_id"]], check_box(x, y, x + w, y + h, where), where, crowd=bool(a.get("iscrowd")))
        rng = a.get("range")
        box.range = float(rng) if isinstance(rng, int | float) and not isinstance(rng, bool) else math.nan
        by_id[a["image_id"]].boxes.append(box)
    return SourceRead(frames, layout=f"COCO {annotations.name}")


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


def _read_supervisely(src: Path) -> SourceRead:
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
    res = SourceRead([], layout="Supervisely project (meta.json, DATASET/img/ + DATASET/ann/)")
    for ds in datasets:
        img_dir, ann_dir = ds / "img", ds / "ann"
        if not ann_dir.is_dir():
            raise MissingInputError(f"{ds}: img/ without ann/ (every image needs ann/NAME.json)")
        imgs = images_under(img_dir, src)
        names = {rel_path(p, img_dir) for p in imgs}
        res.unmatched += [rel_path(p, src) for p in walk_files(ann_dir, src)
                          if p.suffix == ".json" and rel_path(p, ann_dir)[:-5] not in names]
        prefix = "" if ds == src else f"{ds.name}/"
        for img in imgs:
            ann = ann_dir / f"{rel_path(img, img_dir)}.json"
            if not ann.is_file() and not ann.is_symlink():
                raise MissingInputError(f"{img}: its Supervisely annotation {ann} is missing (every image needs one)")
            fr = source_frame(img, prefix + rel_path(img, img_dir), src)
            fr.label = ann
            _supervisely_objects(ann, src, fr, titles, res.stats)
            res.frames.append(fr)
    return res


def _supervisely_objects(ann: Path, src: Path, fr: SourceFrame, titles: set[str], stats: Counter) -> None:
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
        (xa, ya), (xb, yb) = (parse_floats([str(v) for v in p], where, "points.exterior") for p in pts)
        box = check_box(min(xa, xb), min(ya, yb), max(xa, xb), max(ya, yb), where)
        fr.boxes.append(LabelBox(obj["classTitle"], box, where))
