"""KITTI's 3D locations on imported frames: which frame they are in (camera or vehicle), range and
bearing from them, and the camera pose fitted to rows with both boxes, which turns 3D-only cones into
ignore regions (:func:`project_only3d`).

Example:
    >>> [round(v, 3) for v in range_bearing((1.0, 0.5, 10.0), "camera")]
    [10.05, -0.1]
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from weather_gym.core.errors import InputError
from weather_gym.lab.datasets.import_frames import SourceFrame


# ------------------------------------------------------------------------------------ geometry
def recognise_location_frame(frames: list[SourceFrame], requested: str) -> tuple[str, str]:
    """Which frame KITTI 3D locations are in: ``camera`` (x right, z forward) or ``vehicle`` (x forward,
    y left), recognised from which puts the cones on the side of the image their 2D box is on."""
    if requested not in ("auto", "camera", "vehicle", "none"):
        raise InputError(f"location frame must be auto, camera, vehicle or none, got {requested!r}")
    if requested != "auto":
        return requested, f"{requested} (given)"
    votes: Counter[str] = Counter()
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


def _fit_pose(frames: list[SourceFrame], frame: str) -> tuple[np.ndarray, float] | None:
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


def range_bearing(loc: tuple[float, float, float], frame: str) -> tuple[float, float]:
    x, y, z = loc
    if frame == "camera":
        fwd, left = z, -x
    elif frame == "vehicle":
        fwd, left = x, y
    else:
        return math.nan, math.nan
    return math.hypot(fwd, left), math.atan2(left, fwd)




def project_only3d(frames: list[SourceFrame], loc_frame: str) -> dict | None:
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
