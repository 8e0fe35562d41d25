"""The files of a COCO cone set: its fixed names, frames, depth PNGs, ignore-mask PNGs and the
record paths, confined to the set's folder.

:mod:`weather_gym.lab.datasets.coco` reads a set, :mod:`weather_gym.lab.datasets.coco_writer` writes one;
both stand on these.

Example:
    >>> import numpy as np, tempfile, pathlib
    >>> from weather_gym.lab.datasets.coco_files import read_depth_png, write_depth_png
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "d.png"
    >>> write_depth_png(p, np.array([[1.5, 70.0]]))
    >>> read_depth_png(p).tolist()
    [[1.5, 65.53500366210938]]
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from weather_gym.core._image_files import read_image_file
from weather_gym.core._io import resolve_inside, write_image
from weather_gym.core.errors import FileFormatError, MissingInputError

__all__ = ["ANNOTATIONS", "DEPTH_SCALE", "JOURNAL", "read_depth_png", "read_image", "read_mask", "record_path",
           "write_depth_png"]

ANNOTATIONS = "annotations.json"
JOURNAL = "annotations.partial.jsonl"
DEPTH_SCALE = 1000.0  # depth PNG units per metre (millimetres)


def _nonempty_file(path: str | os.PathLike, kind: str) -> Path:
    """``path`` as a Path; FileNotFoundError / ValueError naming it when it is missing or empty."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"{kind} file {path} not found")
    if path.stat().st_size == 0:
        raise FileFormatError(f"{kind} file {path} is empty (0 bytes)")
    return path


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an RGB uint8 image; clear errors for a missing, empty or undecodable file."""
    path = _nonempty_file(path, "image")
    bgr = read_image_file(path, cv2.IMREAD_COLOR)
    if bgr is None or bgr.size == 0:
        raise FileFormatError(f"image file {path} could not be decoded as an image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def write_depth_png(path: str | os.PathLike, depth_m: np.ndarray, *, overwrite: bool = False) -> None:
    """Write float metres as uint16 millimetres (values beyond 65.535 m saturate), safely (``weather_gym.core._io``)."""
    d = np.asarray(depth_m, dtype=np.float64)
    mm = np.clip(np.rint(np.nan_to_num(d, nan=0.0, posinf=65.535) * DEPTH_SCALE), 0, 65535).astype(np.uint16)
    write_image(path, mm, rgb=False, overwrite=overwrite)


def read_depth_png(path: str | os.PathLike) -> np.ndarray:
    """Read a uint16 millimetre depth PNG as float32 metres."""
    path = _nonempty_file(path, "depth")
    mm = read_image_file(path, cv2.IMREAD_UNCHANGED)
    if mm is None or mm.ndim != 2 or mm.dtype != np.uint16:
        raise FileFormatError(f"depth file {path} is not a single-channel 16-bit PNG of millimetres")
    return mm.astype(np.float32) / np.float32(DEPTH_SCALE)


def record_path(root: str | os.PathLike, record: dict, key: str) -> Path:
    """The file an image record's ``key`` (``file_name``, ``depth_file``, a ``track`` CSV) names, resolved
    inside the dataset folder ``root``: an absolute path, a ``..`` or a symlink that leads outside
    raises :class:`~weather_gym.core.errors.OutsideRootError` (a dataset cannot make us read or write
    elsewhere)."""
    return resolve_inside(root, record[key], what=f"{Path(root) / ANNOTATIONS}: image {record.get('id')!r} {key!r}")


def read_mask(path: str | os.PathLike, size: tuple[int, int] | None = None) -> np.ndarray:
    """A mask PNG as a boolean ``(H, W)`` array (True = ignored); ``size`` (W, H) is checked when given."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"ignore mask {path} not found")
    raw = read_image_file(path, cv2.IMREAD_UNCHANGED)
    if raw is None or raw.size == 0:
        raise FileFormatError(f"ignore mask {path} could not be decoded as an image (expected a PNG, white = ignored)")
    if raw.ndim == 3:
        raw = cv2.cvtColor(raw[..., :3], cv2.COLOR_BGR2GRAY)
    if raw.dtype == np.uint16:
        raw = (raw >> 8).astype(np.uint8)  # type: ignore[operator]  # a uint16 image here
    if raw.dtype != np.uint8:
        raise FileFormatError(f"ignore mask {path} has pixel type {raw.dtype}; expected an 8-bit PNG (white = ignored)")
    mask = raw >= 128
    if size is not None and (mask.shape[1], mask.shape[0]) != tuple(size):
        raise FileFormatError(f"ignore mask {path} is {mask.shape[1]}x{mask.shape[0]} but the frames are "
                         f"{size[0]}x{size[1]}; a mask must have the frames' size")
    return mask
