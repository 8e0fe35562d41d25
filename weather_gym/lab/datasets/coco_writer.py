"""Writing a COCO cone set: :class:`CocoWriter`, resumable (a journal of finished frames is kept
until ``close``), one writer per folder.

Example:
    >>> import numpy as np, tempfile
    >>> from weather_gym.lab.datasets.coco_writer import CocoWriter
    >>> with CocoWriter(tempfile.mkdtemp()) as w:
    ...     w.add(np.zeros((8, 12, 3), np.uint8), {"track": "demo"},
    ...           {"boxes": np.array([[1, 1, 5, 7.]]), "classes": np.array([0])})
    0
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from weather_gym.core._io import (
    atomic_write_json,
    check_not_input,
    exclusive,
    open_append,
    write_failure,
    write_image,
)
from weather_gym.core.errors import FileFormatError, InputError, OutputExistsError, OutputPathError
from weather_gym.lab.datasets.coco_files import ANNOTATIONS, JOURNAL, write_depth_png
from weather_gym.perception.labels import CATEGORIES, MIN_BOX_HEIGHT_PX, tiny_mask

__all__ = ["CocoWriter"]


def _same_settings(journal: Path, before: Any, now: dict | None) -> None:
    """Refuse to resume ``journal`` with other settings than the interrupted run's (InputError naming them)."""
    if now is None or before == now:
        return
    if not isinstance(before, dict):
        raise FileFormatError(f"{journal}: its settings line is not a table; pass --overwrite to start again")
    diff = [k for k in sorted(set(before) | set(now)) if before.get(k) != now.get(k)]
    shown = "; ".join(f"{k}: {before.get(k)!r} there, {now.get(k)!r} now" for k in diff[:4])
    raise InputError(f"--resume: {journal} was written with other settings ({', '.join(diff)}): {shown}. "
                     "Resume with the same settings, or pass --overwrite to start again")


class CocoWriter:
    """Write frames into a COCO folder; resumable (a journal of finished frames is kept until ``close``).

    ``add(image, record, gt, depth=None)`` writes ``images/NNNNNN.png`` (``.jpg`` with ``jpeg_quality``:
    4-7x smaller, lossy) and ``depth/NNNNNN.png``, and returns the image id. ``gt`` holds arrays ``boxes`` (xyxy), ``classes`` and optionally
    ``ranges``, ``bearings``, ``cone_ids``, ``pixels``. ``close()`` writes ``annotations.json``
    atomically and removes the journal. An existing ``annotations.json`` is never overwritten unless
    ``overwrite=True``; with ``resume=True`` the journal of an interrupted run is read back and
    ``done`` tells how many frames are already written.
    """

    def __init__(self, root: str | os.PathLike, *, overwrite: bool = False, resume: bool = False,
                 min_box_height: float = MIN_BOX_HEIGHT_PX, info: dict | None = None,
                 jpeg_quality: int | None = None, identity: dict | None = None) -> None:
        self.root = Path(root)
        self.min_box_height = float(min_box_height)
        if jpeg_quality is not None and not (isinstance(jpeg_quality, int) and 1 <= jpeg_quality <= 100):
            raise InputError(f"jpeg_quality must be an integer in 1..100 (None: PNG), got {jpeg_quality!r}")
        self.jpeg_quality = jpeg_quality
        if self.root.exists() and not self.root.is_dir():
            raise OutputPathError(f"dataset folder {self.root} exists and is not a folder")
        check_not_input(self.root, what="dataset folder")
        self.root.mkdir(parents=True, exist_ok=True)
        self._lock = contextlib.ExitStack()  # one writer per folder, held until close() / abort()
        self._lock.enter_context(exclusive(self.root, message=(
            f"another run is writing the dataset {self.root}; wait for it to finish or choose another --out")))
        try:
            self._open(overwrite, resume, info, identity)
        except BaseException:
            self._lock.close()
            raise

    def _open(self, overwrite: bool, resume: bool, info: dict | None, identity: dict | None) -> None:
        ann = self.root / ANNOTATIONS
        if ann.exists() and not overwrite:
            raise OutputExistsError(f"{ann} already exists; choose another --out folder or pass --overwrite")
        journal = self.root / JOURNAL
        if journal.exists() and not (resume or overwrite):
            raise OutputExistsError(f"{journal} exists (an interrupted render): pass --resume to continue it "
                                  "or --overwrite to start again")
        (self.root / "images").mkdir(parents=True, exist_ok=True)
        (self.root / "depth").mkdir(parents=True, exist_ok=True)
        self.images: list[dict] = []
        self.annotations: list[dict] = []
        self.info = dict(info or {})
        settings = None if identity is None else json.loads(json.dumps(identity, default=str))
        fresh = True
        if resume and journal.exists():
            with open(journal, encoding="utf-8", errors="replace") as f:
                for line in f:
                    line = line.strip()
                    if not line:
                        continue
                    try:
                        entry = json.loads(line)
                    except json.JSONDecodeError:
                        break  # a line cut short by the interruption: that frame is redone
                    if "settings" in entry:  # the first line: what the interrupted run was asked for
                        _same_settings(journal, entry["settings"], settings)
                        fresh = False
                        continue
                    self.images.append(entry["image"])
                    self.annotations.extend(entry["annotations"])
            fresh = fresh and not self.images
        elif journal.exists():
            journal.unlink()
        if ann.exists() and overwrite:
            ann.unlink()
        self._journal = open_append(journal)
        if settings is not None and fresh:
            self._journal.write(json.dumps({"settings": settings}) + "\n")
            self._journal.flush()
        self._closed = False

    @property
    def done(self) -> int:
        """Frames already written (from a resumed journal plus this run)."""
        return len(self.images)

    def add(self, image: np.ndarray, record: dict, gt: dict, depth: np.ndarray | None = None) -> int:
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise InputError(f"image must be uint8 (H, W, 3) RGB, got {image.dtype} {image.shape}")
        idx = len(self.images)
        name = f"{idx:06d}.png"
        image_name = name if self.jpeg_quality is None else f"{idx:06d}.jpg"
        params = () if self.jpeg_quality is None else (cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality)
        # the dataset's own frames: a resumed or --overwrite render replaces them (the folder-level check is above)
        write_image(self.root / "images" / image_name, image, overwrite=True, params=params)
        rec = {"id": idx, "file_name": f"images/{image_name}", "width": int(image.shape[1]),
               "height": int(image.shape[0])}
        if depth is not None:
            write_depth_png(self.root / "depth" / name, depth, overwrite=True)
            rec["depth_file"] = f"depth/{name}"
        rec.update(record)
        boxes = np.asarray(gt["boxes"], dtype=np.float64).reshape(-1, 4)
        classes = np.asarray(gt["classes"], dtype=np.int64).reshape(-1)
        tiny = tiny_mask(boxes, self.min_box_height)
        anns = []
        for k in range(boxes.shape[0]):
            x1, y1, x2, y2 = (float(v) for v in boxes[k])
            a = {
                "id": len(self.annotations) + k + 1,
                "image_id": idx,
                "category_id": int(classes[k]) + 1,
                "bbox": [x1, y1, x2 - x1, y2 - y1],
                "area": (x2 - x1) * (y2 - y1),
                "iscrowd": int(tiny[k]),
            }
            for key, out, conv in (("ranges", "range", float), ("bearings", "bearing", float),
                                   ("cone_ids", "cone_id", int), ("pixels", "pixels", int)):
                if key in gt:
                    a[out] = conv(np.asarray(gt[key]).reshape(-1)[k])
            anns.append(a)
        self.images.append(rec)
        self.annotations.extend(anns)
        try:
            self._journal.write(json.dumps({"image": rec, "annotations": anns}) + "\n")
            self._journal.flush()
        except OSError as exc:  # a full disk is the machine's state, not a bug
            raise write_failure(self.root / JOURNAL, exc) from None
        return idx

    def close(self) -> Path:
        """Write ``annotations.json`` and remove the journal; returns the annotations path."""
        if self._closed:
            return self.root / ANNOTATIONS
        self._journal.close()
        data = {
            "info": {"description": "weather-gym rendered cone frames", "min_box_height_px": self.min_box_height,
                     **self.info},
            "images": self.images,
            "annotations": self.annotations,
            "categories": CATEGORIES,
        }
        try:
            atomic_write_json(self.root / ANNOTATIONS, data)
            (self.root / JOURNAL).unlink(missing_ok=True)
        finally:
            self._closed = True
            self._lock.close()
        return self.root / ANNOTATIONS

    def abort(self) -> None:
        """Stop without writing annotations.json (the journal stays, for ``resume=True``)."""
        if not self._closed:
            self._journal.close()
            self._closed = True
        self._lock.close()

    def __enter__(self) -> CocoWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
