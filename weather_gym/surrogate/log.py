"""Logs of the full pipeline for fitting the surrogate: every true cone, every false positive, per frame.

:func:`record` drives episodes through the full pipeline (render -> weather -> the ONNX detector,
``make_env(perception="detector")``) with the ground-truth pure-pursuit driver, so the car moves as it
does in a lap, and ground truth from geometry (``ground_truth="geometry"``: exactly the cones the
surrogate later sees in ``gt_cones`` mode). On each frame detections are matched to the visible
cones the way the project's scoring does: greedily by score, IoU >= 0.5 on the boxes (here
class-agnostic, so that a cone reported in the wrong colour counts as detected with a confused
class); unmatched detections are false positives.

Tables (one :class:`SurrogateLog`, saved as one ``.npz`` by :func:`save_log`):

* ``cones`` - one row per frame and visible cone: ``episode``, ``frame``, ``cone_id`` (stable over the
  episode: the track's cone index), ``cls``, ``range`` (m), ``bearing`` (rad), ``box`` (xyxy px),
  ``box_h`` (px), ``pixels`` (visible), ``visibility`` (visible box height / the unoccluded cone's
  height at that range, 0..1: occlusion and image borders), ``speed`` (m/s), ``yaw_rate`` (rad/s),
  ``detected``, ``det_cls`` (-1 if missed), ``det_score``, ``range_err`` and ``bearing_err``
  (detected - true; NaN if missed).
* ``fps`` - one row per false positive: ``episode``, ``frame``, ``range``, ``bearing``, ``cls``,
  ``score``, ``box``.
* ``frames`` - one row per frame: ``episode``, ``frame``, ``n_gt``, ``n_fp``, ``speed``, ``yaw_rate``.
* ``episodes`` - per episode: track, weather spec, condition, k, seed, steps.

Example:
    >>> import numpy as np
    >>> from weather_gym.surrogate.log import match_detections
    >>> gt = np.array([[10, 10, 30, 50.], [100, 10, 120, 50.]])
    >>> det = np.array([[101, 11, 120, 50.], [11, 10, 30, 49.], [200, 0, 210, 9.]])
    >>> match_detections(gt, det, np.array([0.9, 0.8, 0.7])).tolist()   # detection -> cone (-1: false positive)
    [1, 0, -1]
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core._io import atomic_file, check_output
from weather_gym.core.cone_spec import CONE_CLASSES, CONE_HEIGHT_M
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError

__all__ = ["LOG_SCHEMA", "SurrogateLog", "match_detections", "visibility", "save_log", "load_log",
           "concat_logs", "loose_matches", "part_matches", "CONE_COLUMNS", "FP_COLUMNS", "FRAME_COLUMNS"]

LOG_SCHEMA = 1
IOU_MATCH = 0.5
_HEIGHTS = np.array([CONE_HEIGHT_M[c] for c in CONE_CLASSES])

CONE_COLUMNS: dict[str, str] = {
    "episode": "int32", "frame": "int32", "cone_id": "int32", "cls": "int8", "range": "float32",
    "bearing": "float32", "box": "float32", "box_h": "float32", "pixels": "int32", "visibility": "float32",
    "speed": "float32", "yaw_rate": "float32", "detected": "bool", "det_cls": "int8", "det_score": "float32",
    "range_err": "float32", "bearing_err": "float32",
}
FP_COLUMNS: dict[str, str] = {"episode": "int32", "frame": "int32", "range": "float32", "bearing": "float32",
                              "cls": "int8", "score": "float32", "box": "float32"}
FRAME_COLUMNS: dict[str, str] = {"episode": "int32", "frame": "int32", "n_gt": "int32", "n_fp": "int32",
                                 "speed": "float32", "yaw_rate": "float32"}
_TABLES = {"cones": CONE_COLUMNS, "fps": FP_COLUMNS, "frames": FRAME_COLUMNS}


@dataclass
class SurrogateLog:
    """The three tables (dicts of equal-length columns) and the episodes they came from."""

    cones: dict[str, np.ndarray]
    fps: dict[str, np.ndarray]
    frames: dict[str, np.ndarray]
    episodes: list[dict[str, Any]] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(len(self.frames["frame"]))

    def select(self, episodes: Sequence[int]) -> SurrogateLog:
        """The rows of the given episode indices (renumbered from 0 in that order)."""
        remap = {int(e): i for i, e in enumerate(episodes)}

        def cut(table: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
            keep = np.isin(table["episode"], list(remap))
            out = {k: v[keep] for k, v in table.items()}
            out["episode"] = np.array([remap[int(e)] for e in out["episode"]], np.int32)
            return out

        return SurrogateLog(cut(self.cones), cut(self.fps), cut(self.frames),
                            [self.episodes[int(e)] for e in episodes], dict(self.meta))


def _iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ix = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    iy = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = ix * iy
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(union > 0, inter / union, 0.0)


def match_detections(gt_boxes: np.ndarray, det_boxes: np.ndarray, det_scores: np.ndarray,
                     iou: float = IOU_MATCH) -> np.ndarray:
    """For each detection the index of the true cone it matches (-1: a false positive).

    COCO's greedy rule: detections in order of decreasing score each take the unmatched true box of
    highest IoU, if that IoU is at least ``iou`` (class-agnostic).
    """
    g = np.asarray(gt_boxes, np.float64).reshape(-1, 4)
    d = np.asarray(det_boxes, np.float64).reshape(-1, 4)
    out = np.full(len(d), -1, np.int64)
    if not len(g) or not len(d):
        return out
    ious = _iou_matrix(d, g)
    taken = np.zeros(len(g), bool)
    for j in np.argsort(-np.asarray(det_scores, np.float64).reshape(len(d)), kind="stable"):
        row = np.where(taken, -1.0, ious[j])
        k = int(np.argmax(row))
        if row[k] >= iou:
            out[j] = k
            taken[k] = True
    return out


def visibility(boxes: np.ndarray, classes: np.ndarray, ranges: np.ndarray, bearings: np.ndarray,
               camera: CameraConfig) -> np.ndarray:
    """Visible box height / the whole cone's image height at its range (0..1; occlusion, image border).

    Example:
        >>> import numpy as np
        >>> from weather_gym.camera.config import CameraConfig
        >>> v = visibility(np.array([[0, 0, 5, 14.]]), np.array([1]), np.array([5.0]), np.array([0.0]), CameraConfig())
        >>> round(float(v[0]), 2)
        0.64
    """
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    z = np.maximum(np.asarray(ranges, np.float64) * np.cos(np.asarray(bearings, np.float64)), 0.1)
    full = camera.fy * _HEIGHTS[np.asarray(classes, np.int64)] / z
    return np.clip((b[:, 3] - b[:, 1]) / np.maximum(full, 1e-6), 0.0, 1.0).astype(np.float32)


class _Recorder:
    """Collects the rows of one episode from ``info["gt"]`` and ``info["detections"]``."""

    def __init__(self, episode: int, camera: CameraConfig) -> None:
        self.episode, self.camera = episode, camera
        self.cones: dict[str, list] = {k: [] for k in CONE_COLUMNS}
        self.fps: dict[str, list] = {k: [] for k in FP_COLUMNS}
        self.frames: dict[str, list] = {k: [] for k in FRAME_COLUMNS}

    def __call__(self, step: int, obs: Any, info: dict, done: bool) -> None:
        gt, det = info.get("gt"), info.get("detections")
        if gt is None or det is None:
            raise InputError("surrogate log: the env gives no info['gt'] / info['detections'] (perception 'detector' "
                             "with ground truth)")
        n = int(len(gt["classes"]))
        gb = np.asarray(gt["boxes"], np.float64).reshape(n, 4)
        gc = np.asarray(gt["classes"], np.int64).reshape(n)
        gr = np.asarray(gt["ranges"], np.float64).reshape(n)
        gbe = np.asarray(gt["bearings"], np.float64).reshape(n)
        m = int(len(det["scores"]))
        db = np.asarray(det["boxes"], np.float64).reshape(m, 4)
        ds = np.asarray(det["scores"], np.float64).reshape(m)
        dc = np.asarray(det["classes"], np.int64).reshape(m)
        dr = np.asarray(det["ranges"], np.float64).reshape(m)
        dbe = np.asarray(det["bearings"], np.float64).reshape(m)
        to_gt = match_detections(gb, db, ds)
        of_gt = np.full(n, -1, np.int64)
        of_gt[to_gt[to_gt >= 0]] = np.flatnonzero(to_gt >= 0)
        hit = of_gt >= 0
        j = np.where(hit, of_gt, 0)
        speed, yaw = float(info.get("speed", math.nan)), float(info.get("yaw_rate", math.nan))
        c = self.cones
        c["episode"].append(np.full(n, self.episode))
        c["frame"].append(np.full(n, step))
        c["cone_id"].append(np.asarray(gt["cone_ids"], np.int64).reshape(n))
        c["cls"].append(gc)
        c["range"].append(gr)
        c["bearing"].append(gbe)
        c["box"].append(gb)
        c["box_h"].append(gb[:, 3] - gb[:, 1])
        c["pixels"].append(np.asarray(gt["pixels"], np.int64).reshape(n))
        c["visibility"].append(visibility(gb, gc, gr, gbe, self.camera))
        c["speed"].append(np.full(n, speed))
        c["yaw_rate"].append(np.full(n, yaw))
        c["detected"].append(hit)
        c["det_cls"].append(np.where(hit, dc[j] if m else -1, -1))
        c["det_score"].append(np.where(hit, ds[j] if m else np.nan, np.nan))
        c["range_err"].append(np.where(hit, (dr[j] if m else np.nan) - gr, np.nan))
        c["bearing_err"].append(np.where(hit, (dbe[j] if m else np.nan) - gbe, np.nan))
        fp = to_gt < 0
        k = int(fp.sum())
        f = self.fps
        f["episode"].append(np.full(k, self.episode))
        f["frame"].append(np.full(k, step))
        f["range"].append(dr[fp])
        f["bearing"].append(dbe[fp])
        f["cls"].append(dc[fp])
        f["score"].append(ds[fp])
        f["box"].append(db[fp])
        fr = self.frames
        for key, value in (("episode", self.episode), ("frame", step), ("n_gt", n), ("n_fp", k),
                           ("speed", speed), ("yaw_rate", yaw)):
            fr[key].append(np.array([value]))


def _stack(parts: dict[str, list], columns: dict[str, str]) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for key, dtype in columns.items():
        chunks = parts.get(key, [])
        if key == "box":
            out[key] = (np.concatenate(chunks).reshape(-1, 4) if chunks else np.zeros((0, 4))).astype(dtype)
        else:
            out[key] = (np.concatenate(chunks) if chunks else np.zeros(0)).astype(dtype)
    return out


def concat_logs(logs: Sequence[SurrogateLog]) -> SurrogateLog:
    """One log of several (episodes renumbered in order)."""
    if not logs:
        raise InputError("concat_logs: no logs given")
    offset = 0
    tables: dict[str, dict[str, list]] = {name: {k: [] for k in cols} for name, cols in _TABLES.items()}
    episodes: list[dict[str, Any]] = []
    for log in logs:
        for name, cols in _TABLES.items():
            t = getattr(log, name)
            for k in cols:
                tables[name][k].append(t[k] + offset if k == "episode" else t[k])
        episodes += log.episodes
        offset += len(log.episodes)
    return SurrogateLog(*(_stack(tables[name], cols) for name, cols in _TABLES.items()), episodes, dict(logs[0].meta))  # type: ignore[call-arg, arg-type]  # the three tables


def save_log(log: SurrogateLog, path: str | os.PathLike, *, overwrite: bool = False) -> str:
    """Write ``log`` as one compressed ``.npz`` (``cones/range``, ..., and ``meta`` JSON); returns the path."""
    check_output(path, overwrite=overwrite, suffixes=(".npz",), what="surrogate log")
    arrays = {f"{name}/{k}": v for name in _TABLES for k, v in getattr(log, name).items()}
    meta = {**log.meta, "schema": LOG_SCHEMA, "episodes": log.episodes}
    arrays["meta"] = np.array(json.dumps(meta))
    with atomic_file(path, "wb", overwrite=overwrite, encoding=None) as f:
        np.savez_compressed(f, **arrays)
    return str(path)


MAX_NPZ_BYTES = 8 << 30
"""Largest total array size (bytes, uncompressed) a surrogate ``.npz`` may declare: logs of a few
hundred laps take a few hundred MB."""


def _check_npz_headers(path: str, where: str) -> None:
    """Read every array's ``.npy`` header (not its data) and refuse shapes the file cannot hold or
    that exceed :data:`MAX_NPZ_BYTES`, before NumPy allocates them (:class:`FileFormatError`)."""
    total = 0
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with zf.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    read = {(1, 0): np.lib.format.read_array_header_1_0,
                            (2, 0): np.lib.format.read_array_header_2_0}.get(version)
                    if read is None:
                        raise FileFormatError(f"{where}: array {info.filename[:-4]!r} has .npy format {version}")
                    shape, _, dtype = read(f, max_header_size=10000)
                    header = f.tell() if f.seekable() else None
                if dtype.hasobject:
                    raise FileFormatError(f"{where}: array {info.filename[:-4]!r} holds Python objects")
                n = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if header is not None and n != info.file_size - header:
                    raise FileFormatError(f"{where}: array {info.filename[:-4]!r} declares shape {shape} "
                                          f"({n} bytes) but holds {info.file_size - header} bytes")
                total += n
                if total > MAX_NPZ_BYTES:
                    raise FileFormatError(f"{where}: its arrays declare more than {MAX_NPZ_BYTES >> 30} GiB")
    except FileFormatError:
        raise
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise FileFormatError(f"{where}: not a readable .npz file ({exc})") from None


def read_npz(path: str, where: str, kind: str, schema: int) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and the JSON ``meta`` of a surrogate ``.npz`` file (a log or a model) whose
    ``meta.schema`` is ``schema``; :class:`FileFormatError` (or :class:`MissingInputError`) naming
    ``where`` and what is wrong."""
    if not os.path.isfile(path):
        raise MissingInputError(f"{where} does not exist")
    _check_npz_headers(path, where)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError) as exc:
        raise FileFormatError(f"{where}: not a readable .npz file ({exc})") from None
    if "meta" not in data:
        raise FileFormatError(f"{where}: no 'meta' entry (not a weather-gym {kind})")
    try:
        meta = json.loads(str(data["meta"]))
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"{where}: 'meta' is not JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("schema") != schema:
        got = meta.get("schema") if isinstance(meta, dict) else None
        raise FileFormatError(f"{where}: schema {got!r}, expected {schema}")
    return data, meta


def load_log(path: str | os.PathLike) -> SurrogateLog:
    """Read a log written by :func:`save_log`; :class:`FileFormatError` naming what is wrong."""
    p = os.fspath(path)
    data, meta = read_npz(p, f"surrogate log {p}", "surrogate log", LOG_SCHEMA)
    tables = {}
    for name, cols in _TABLES.items():
        t = {}
        for k, dtype in cols.items():
            key = f"{name}/{k}"
            if key not in data:
                raise FileFormatError(f"surrogate log {p}: missing column {key!r}")
            t[k] = np.asarray(data[key]).astype(dtype, copy=False)
        lengths = {k: len(v) for k, v in t.items()}
        if len(set(lengths.values())) > 1:
            raise FileFormatError(f"surrogate log {p}: table {name!r} has columns of different lengths {lengths}")
        tables[name] = t
    episodes = meta.pop("episodes", [])
    if not isinstance(episodes, list) or not all(isinstance(e, dict) and {"condition", "k"} <= set(e) for e in episodes):
        raise FileFormatError(f"surrogate log {p}: 'episodes' must be a list of tables with condition and k")
    for i, e in enumerate(episodes):
        if not isinstance(e["condition"], str) or isinstance(e["k"], bool) or not isinstance(e["k"], int | float) \
                or not np.isfinite(e["k"]):
            raise FileFormatError(f"surrogate log {p}: episode {i}: 'condition' must be a name and 'k' a finite "
                                  f"number, got {e['condition']!r} and {e['k']!r}")
        if e["condition"] != "clear" and not isinstance(e.get("weather"), str | dict | list):
            raise FileFormatError(f"surrogate log {p}: episode {i} ({e['condition']}) has no 'weather' spec "
                                  "(the effect and its parameters the episode was driven in)")
    for name, t in tables.items():
        if len(t["episode"]) and (t["episode"].min() < 0 or t["episode"].max() >= len(episodes)):
            raise FileFormatError(f"surrogate log {p}: table {name!r} names an episode outside 0..{len(episodes) - 1}")
    return SurrogateLog(tables["cones"], tables["fps"], tables["frames"], episodes, meta)


LOOSE_IOU = 0.1
"""A false positive overlapping a missed cone by at least this IoU is that cone's *loose* detection."""


def _frames_of(log: SurrogateLog, which: np.ndarray):
    """For each frame with a false positive among ``which`` (a mask over ``log.fps``): the indices of
    those false positives and the ``cones`` rows of the same frame."""
    c, f = log.cones, log.fps
    if not which.any():
        return
    ckey = c["episode"].astype(np.int64) * 10_000_000 + c["frame"]
    fkey = f["episode"].astype(np.int64) * 10_000_000 + f["frame"]
    corder = np.argsort(ckey, kind="stable")
    cks = ckey[corder]
    for key in np.unique(fkey[which]):
        lo, hi = np.searchsorted(cks, key), np.searchsorted(cks, key, side="right")
        yield np.flatnonzero((fkey == key) & which), corder[lo:hi]


def loose_matches(log: SurrogateLog, iou: float = LOOSE_IOU) -> np.ndarray:
    """For each false positive the ``cones`` row of the missed cone it loosely matches (-1: none).

    Most of the detector's false positives are small, far cones boxed a pixel or two off (IoU
    between 0.1 and 0.5 with the true box): a scoring miss plus a false positive, but to a planner
    a cone roughly where it is. Greedy by score, IoU >= ``iou``, among the cones of the same frame
    that no detection matched.
    """
    c, f = log.cones, log.fps
    out = np.full(len(f["frame"]), -1, np.int64)
    for fi, rows in _frames_of(log, np.ones(len(out), bool)):
        rows = rows[~c["detected"][rows]]
        if not len(rows):
            continue
        to = match_detections(c["box"][rows], f["box"][fi], f["score"][fi], iou=iou)
        hit = to >= 0
        out[fi[hit]] = rows[to[hit]]
    return out


def part_matches(log: SurrogateLog, loose: np.ndarray | None = None) -> np.ndarray:
    """For each false positive the ``cones`` row it is a *part detection* of (-1: none).

    A false positive that is not a loose detection (``loose``, from :func:`loose_matches`) and whose box
    centre lies inside a cone's box is that cone's: a box on a near cone's stripe, on one cone of an
    overlapping pair, on part of a far one. Of several such cones, the one whose box centre is nearest
    (in units of its box height).
    """
    c, f = log.cones, log.fps
    out = np.full(len(f["frame"]), -1, np.int64)
    todo = np.ones(len(out), bool) if loose is None else np.asarray(loose) < 0
    for fi, rows in _frames_of(log, todo):
        if not len(rows):
            continue
        b = np.asarray(c["box"][rows], np.float64)
        fb = np.asarray(f["box"][fi], np.float64)
        cx, cy = (fb[:, 0] + fb[:, 2]) / 2, (fb[:, 1] + fb[:, 3]) / 2
        inside = ((cx[:, None] >= b[None, :, 0]) & (cx[:, None] <= b[None, :, 2])
                  & (cy[:, None] >= b[None, :, 1]) & (cy[:, None] <= b[None, :, 3]))
        h = np.maximum(b[:, 3] - b[:, 1], 1.0)
        dist = np.hypot(cx[:, None] - (b[None, :, 0] + b[None, :, 2]) / 2, cy[:, None] - (b[None, :, 1] + b[None, :, 3]) / 2)
        dist = np.where(inside, dist / h[None, :], np.inf)
        best = np.argmin(dist, axis=1)
        ok = np.isfinite(dist[np.arange(len(fi)), best])
        out[fi[ok]] = rows[best[ok]]
    return out
