"""Cone CSV files (the Formula Student simulators' ``tag,x,y[,direction,...]``): reading and
validating one (:func:`read_cone_csv`), and building a :class:`~weather_gym.tracks.Track` from it
(:func:`track_from_csv`). Re-exported by :mod:`weather_gym.tracks`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import NoReturn

import numpy as np
from scipy.spatial import cKDTree

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import FileFormatError, InputError, LimitError, MissingInputError
from weather_gym.tracks import _layout as layout
from weather_gym.tracks._track import CSV_HEADER, EVENTS, Track

__all__ = ["DUPLICATE_TOL_M", "MAX_CONES", "MAX_COORDINATE_M", "MAX_TRACK_FILE_BYTES", "read_cone_csv",
           "track_from_csv"]

DUPLICATE_TOL_M = 0.01
MAX_TRACK_FILE_BYTES = 10_000_000
"""Largest cone CSV read (EUFS tracks are a few kB)."""
MAX_CONES = 10_000
"""Most cones in a track (the largest shipped track has a few hundred)."""
MAX_COORDINATE_M = 100_000.0
"""Cone positions lie within this distance of the origin (100 km)."""


def _fail(path: str | os.PathLike[str], line_no: int | None, msg: str) -> NoReturn:
    where = f"{path}: line {line_no}: " if line_no is not None else f"{path}: "
    raise FileFormatError(where + msg)


def _body(path: Path) -> list[tuple[int, str]]:
    """The non-blank, non-comment lines of a (size-checked, UTF-8) cone CSV with their 1-based numbers."""
    if not path.exists():
        raise MissingInputError(f"track file {path} not found")
    if not path.is_file():
        raise FileFormatError(f"track file {path} is not a regular file")
    if path.stat().st_size > MAX_TRACK_FILE_BYTES:
        raise LimitError(f"track file {path} is {path.stat().st_size / 1e6:.1f} MB; a cone CSV is at most "
                         f"{MAX_TRACK_FILE_BYTES / 1e6:.0f} MB")
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: not a UTF-8 text file ({exc.reason})") from None
    return [(i + 1, ln.strip()) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]


def _position(path: Path, no: int, col: str, raw: str) -> float:
    try:
        v = float(raw)
    except ValueError:
        _fail(path, no, f"{col} = {raw!r} is not a number")
    if not math.isfinite(v):
        _fail(path, no, f"{col} = {raw!r}: positions must be finite numbers")
    if abs(v) > MAX_COORDINATE_M:
        raise LimitError(f"{path}: line {no}: {col} = {raw}: positions must lie within +-{MAX_COORDINATE_M:g} m")
    return v


def _start_yaw(path: Path, no: int, fields: list[str], has_direction: bool) -> float | None:
    """The ``direction`` of a ``car_start`` row (None when the file has no such column or it is empty)."""
    if not (has_direction and len(fields) > 3 and fields[3]):
        return None
    try:
        yaw = float(fields[3])
    except ValueError:
        _fail(path, no, f"direction = {fields[3]!r} is not a number")
    if not math.isfinite(yaw):
        _fail(path, no, f"direction = {fields[3]!r}: must be a finite angle in radians")
    return yaw


def _check_cones(path: Path, cones: np.ndarray, classes: np.ndarray, line_nos: list[int]) -> None:
    """No two cones within 1 cm, and both boundaries present."""
    pairs = sorted(cKDTree(cones).query_pairs(DUPLICATE_TOL_M))
    if pairs:
        i, j = min(pairs, key=lambda p: max(p))
        _fail(path, line_nos[j], f"{CONE_CLASSES[classes[j]]} cone at ({cones[j, 0]:g}, {cones[j, 1]:g}) "
                                 f"duplicates the cone in line {line_nos[i]} (closer than 1 cm)")
    for cid, what in ((0, "left"), (1, "right")):
        if not (classes == cid).any():
            _fail(path, None, f"no {CONE_CLASSES[cid]} cones: a track needs a {what} ({CONE_CLASSES[cid]}) boundary")


def read_cone_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """Read and validate a cone CSV: ``(cones_xy (N, 2), cone_classes (N,), start_pose or None)``.

    Rows tagged ``car_start`` give the start pose ``(x, y, yaw)`` (yaw from the ``direction``
    column; ``None`` if the file has none); ``midpoint`` rows are markers and are skipped; blank
    lines and ``#`` comments are ignored. Errors name the file and the 1-based line.

    Example:
        >>> from weather_gym.core.paths import data_dir
        >>> xy, cls, start = read_cone_csv(data_dir("tracks") / "eufs" / "acceleration.csv")
        >>> xy.shape, start
        ((46, 2), (-53.0, 0.0, 0.0))
    """
    path = Path(path)
    body = _body(path)
    expected = f"a header line 'tag,x,y' or '{CSV_HEADER}'"
    if not body:
        _fail(path, None, f"empty file; expected {expected} followed by one cone per line")
    head_no, head = body[0]
    header = [h.strip().lower() for h in head.split(",")]
    if header[:3] != ["tag", "x", "y"]:  # the line is not quoted: the file may be anything (a system file)
        _fail(path, head_no, f"missing header: expected {expected}; is this a cone CSV file?")
    has_direction = len(header) > 3 and header[3] == "direction"
    tags, xy, line_nos, start, start_line = [], [], [], None, None
    valid = ", ".join(CONE_CLASSES)
    for no, text in body[1:]:
        fields = [f.strip() for f in text.split(",")]
        if len(fields) < 3:
            _fail(path, no, f"expected at least 3 comma-separated fields (tag,x,y), got {len(fields)}")
        tag = fields[0].lower()
        if tag == "midpoint":
            continue
        if tag not in CONE_CLASSES and tag != "car_start":
            _fail(path, no, f"unknown cone colour tag {fields[0]!r}; expected one of {valid} "
                            "(or car_start / midpoint)")
        vals = [_position(path, no, "x", fields[1]), _position(path, no, "y", fields[2])]
        if tag == "car_start":
            if start is not None:
                _fail(path, no, f"second car_start row (the first is in line {start_line})")
            start, start_line = (vals[0], vals[1], _start_yaw(path, no, fields, has_direction)), no
            continue
        tags.append(CONE_CLASSES.index(tag))
        xy.append(vals)
        line_nos.append(no)
        if len(xy) > MAX_CONES:
            raise LimitError(f"{path}: more than {MAX_CONES} cones; a track has at most {MAX_CONES}")
    if not xy:
        _fail(path, None, "no cones after the header")
    cones = np.array(xy, dtype=np.float64)
    classes = np.array(tags, dtype=np.int64)
    _check_cones(path, cones, classes, line_nos)
    return cones, classes, start


def track_from_csv(path: str | os.PathLike, *, name: str | None = None, event: str | None = None) -> Track:
    """Build a :class:`Track` from a cone CSV. ``event``: None infers trackdrive (closed loop) or
    acceleration (open lane); "skidpad" builds the skidpad sequence from circle fits."""
    path = Path(path)
    if event is not None and event not in EVENTS:
        raise InputError(f"unknown event {event!r}; expected one of {', '.join(EVENTS)}")
    cones, classes, start = read_cone_csv(path)
    builder = layout.skidpad_from_cones if event == "skidpad" else layout.layout_from_cones
    fields = builder(cones, classes, start, str(path))
    if event is not None and fields["event"] != event:
        raise InputError(f"{path}: event {event!r} expected, but the cones form a "
                         f"{'closed loop' if fields['closed'] else 'open lane'} ({fields['event']})")
    return Track(name=name or path.stem, cones_xy=cones, cone_classes=classes, source=str(path), **fields)
