"""Import labelled camera recordings (KITTI, YOLO txt, COCO, Supervisely/FSOCO) into the project's COCO layout.

``weather-gym dataset import {kitti,yolo,coco,supervisely} SRC --out DIR`` (:func:`import_dataset`) reads
a folder of frames and labels, validates all of it first, then copies the frames (byte for byte) into
``DIR/images/`` and writes ``DIR/annotations.json``; nothing outside ``DIR`` is written.

* **Confinement**: every file read from SRC (frames, label and calibration files, ``classes.txt``,
  ``data.yaml``, JSON files, linked sub-folders) must resolve inside SRC (:mod:`weather_gym.core._confine`);
  a link that leads out is an error naming the link, and nothing is read through it. Text files must
  be UTF-8. Frames must lie within :func:`~weather_gym.core.limits.check_image_size` (checked from the
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
    >>> from weather_gym.lab.datasets.importers import parse_class_map
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
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from weather_gym.camera.config import CameraConfig
from weather_gym.core._confine import read_bytes, read_text
from weather_gym.core._image_files import CONVERSIONS, colour_conversions, conversion_note
from weather_gym.core._io import atomic_write, atomic_write_json, file_id, resolve_inside
from weather_gym.core._lock import exclusive_folder
from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import (
    FileFormatError,
    InputError,
    MissingInputError,
    OutputExistsError,
    OutputPathError,
)
from weather_gym.lab.datasets.coco import ANNOTATIONS
from weather_gym.lab.datasets.import_frames import IMAGE_EXTS, SourceFrame, image_size
from weather_gym.lab.datasets.import_geometry import (
    MIN_POSE_ROWS,
    project_only3d,
    range_bearing,
    recognise_location_frame,
)
from weather_gym.lab.datasets.import_readers import read_source
from weather_gym.lab.datasets.masks import MASK_FILE, read_mask, write_mask
from weather_gym.perception.labels import CATEGORIES, DEFAULT_CLASSES, IGNORE, SmallRule, parse_class_map
from weather_gym.weather.presets import canonical_condition, conditions

__all__ = ["FORMATS", "DEFAULT_CLASSES", "IGNORE", "MIN_POSE_ROWS", "PARTIAL", "parse_class_map", "parse_intrinsics",
           "import_dataset", "IMAGE_EXTS"]

FORMATS = ("kitti", "yolo", "coco", "supervisely")


# ------------------------------------------------------------------------------------ arguments
def parse_intrinsics(spec: str | Sequence[float] | Mapping[str, float] | None) -> dict[str, float] | None:
    """``"fx,fy,cx,cy"`` (pixels at the image size), a 4-sequence or a mapping -> ``{fx, fy, cx, cy}``."""
    if spec is None:
        return None
    if isinstance(spec, Mapping):
        vals: list[Any] = [spec.get(k) for k in ("fx", "fy", "cx", "cy")]
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
                         f"({', '.join(conditions())}, or the effect names droplets, dim)") from None
    if severity is None or not 1 <= int(severity) <= 4:
        raise InputError(f"--condition {condition} needs --severity 1-4, got {severity}")
    return c, int(severity)


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


def _identity(fmt: str, src: Path, frames: list[SourceFrame], settings: dict[str, Any]) -> dict[str, Any]:
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
    with import_folder(out, src, overwrite, resume) as state:
        return _import(fmt, src, out, state, cmap=cmap, cond=cond, sev=sev, given_k=given_k, detector=detector,
                       mask=mask, annotations=annotations, location_frame=location_frame,
                       project_3d=project_3d, progress=progress)


@contextlib.contextmanager
def import_folder(out: Path, src: Path, overwrite: bool, resume: bool) -> Iterator[str]:
    """``--out`` of an import, made and held by this import alone (the project's lock); yields its state
    (new, resume, overwrite: :func:`_out_state`, checked before anything is made and again under the
    lock). A folder this import made is removed again when it fails before writing anything."""
    _out_state(out, src, overwrite, resume)  # refuse early, before anything is made
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(f"cannot make --out {out}: {exc.strerror or exc}") from None
    try:
        with exclusive_folder(out, busy=f"another import is writing into {out}; wait for it to finish or choose "
                                        "another --out folder"):
            yield _out_state(out, src, overwrite, resume)  # again, now that no other writer can change it
    except BaseException:
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()  # only when nothing was written
        raise


def _import(fmt: str, src: Path, out: Path, state: str, *, cmap: dict[str, str], cond: str | None,  # noqa: C901
            sev: int | None, given_k: dict[str, float] | None, detector: Any, mask: Any, annotations: Any,
            location_frame: str, project_3d: bool, progress: bool) -> dict[str, Any]:
    # 1. read and validate everything before writing anything
    read = read_source(fmt, src, Path(annotations) if annotations is not None else None)
    frames, stats = read.frames, read.stats
    if not frames:
        raise FileFormatError(f"{src}: no frames to import")
    converted: Counter = Counter()
    n_converted = 0
    for fr in tqdm(frames, desc="check", unit="frame", disable=not progress):
        if fr.size == (0, 0):
            fr.size = image_size(fr, src)
        conv = colour_conversions(fr.image)  # frames are stored as they are; readers decode them as 8-bit RGB
        converted.update(conv)
        n_converted += bool(conv)
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
    loc_frame, loc_why = recognise_location_frame(frames, location_frame) if fmt == "kitti" else ("none", "none")
    projected = project_only3d(frames, loc_frame) if fmt == "kitti" and project_3d else None
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
    images: list[dict[str, Any]] = []
    anns: list[dict[str, Any]] = []
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
            rng, bear = (range_bearing(b.location, loc_frame) if b.location is not None else (b.range, b.bearing))
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
        "read_as_8bit_rgb": {"frames": n_converted, **{k: converted[k] for k in CONVERSIONS if converted[k]}},
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
            "resumed": n_kept if state == "resume" else None,
            "converted": None if not n_converted else conversion_note(
                {k: converted[k] for k in CONVERSIONS}, f"{n_converted} frame(s) that are not 8-bit colour (stored as "
                "they are)")}


def _clear_but_marker(out: Path) -> None:
    """Remove the dataset ``out`` held (its frames, masks, annotations), keeping the new import's marker."""
    marker = (out / PARTIAL).read_bytes()
    _clear(out)
    atomic_write(out / PARTIAL, marker)


def _sizes_text(sizes: Mapping[tuple[int, int], int]) -> str:
    return ", ".join(f"{w}x{h} ({n})" for (w, h), n in sorted(sizes.items()))
