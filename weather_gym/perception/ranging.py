"""From detections to cones: class, score, bearing (pinhole model) and range (depth map or box height).

Range, two ways (``ranges_source`` tells which one each cone used):

* **depth** (as the reference study did with the ZED's stereo depth): the median z-depth of the
  central part of the box (middle 50 % of its width, 20-80 % of its height, so background pixels
  beside the cone's slanted sides are left out), converted to a point in the level camera frame
  (undoing the camera's pitch), then horizontal distance, plus the cone's mean radius (the
  surface seen is in front of the cone's axis). The median is robust to a few background pixels
  and to droplets over part of the cone. ``depth_quantile`` takes a lower quantile instead: for far
  cones (5-8 px boxes, placed a pixel or two off) the central part is partly background and the
  median ranges them metres too long, while the cone is still the nearest surface there (0.25 took
  the share of matched cones standing clear at 15-20 m more than 1 m off from 0.33 to 0.00 on rendered frames;
  docs/perception.md, "Far cones and the depth quantile").
* **far**: the depth map says there is nothing inside the box closer than the camera's far plane
  (every pixel of its central part is at ``camera.far``, e.g. a detection in the sky): the range is
  ``camera.far``. A box height would put such a false detection a few metres in front of the car;
  the depth map already says it is not there, so downstream range gates drop it.
* **height** (no depth given, or no valid depth inside the box, e.g. stereo holes):
  ``fy * cone_height / box_height`` (z-distance of an upright cone of known height), divided by
  ``cos(bearing)``. This is biased for cones cut by the image border or occluded (their box is
  shorter) - documented, not hidden.

Bearing: ``atan2(cx - u, fx)`` at the box's horizontal centre (positive left), as in the env's
ground truth. A camera with lens distortion (``weather_gym.camera.isp``) is used as a calibrated
stack would: ``undistort`` maps the box's image points back to the pinhole image first (the box
centre for the bearing and the depth's direction, its top and bottom centre for the box height);
the depth is still read inside the box as the frame shows it.

Example:
    >>> import numpy as np
    >>> from weather_gym.camera.config import CameraConfig
    >>> from weather_gym.perception.ranging import detections_to_cones
    >>> cam = CameraConfig()
    >>> det = {"boxes": np.array([[326, 180, 346, 201.8]]), "scores": np.array([0.9]), "classes": np.array([1])}
    >>> c = detections_to_cones(det, cam)
    >>> round(float(c["ranges"][0]), 2), round(float(c["bearings"][0]), 3), c["ranges_source"].tolist()
    (5.01, 0.0, ['height'])
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import CONE_BASE_M, CONE_CLASSES, CONE_HEIGHT_M
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import DEFAULT_MAX_CONES, pack_cones

__all__ = ["DEPTH_QUANTILE", "check_depth_quantile", "detections_to_cones", "cones_to_observation", "range_from_depth",
           "range_from_box_height"]

_HEIGHTS = np.array([CONE_HEIGHT_M[c] for c in CONE_CLASSES])
_MEAN_RADIUS = np.array([CONE_BASE_M[c] / 4.0 for c in CONE_CLASSES])  # radius at mid-height

DEPTH_QUANTILE = 0.5
"""The default quantile of the depths inside a box that gives its range: the median."""


def check_depth_quantile(q: float) -> float:
    """``q`` as a float if it is a quantile in (0, 1], else an ``InputError`` naming it."""
    if isinstance(q, bool) or not isinstance(q, (int, float)) or not 0.0 < float(q) <= 1.0:
        raise InputError(f"depth_quantile must be a number in (0, 1] (0.5: the median), got {q!r}")
    return float(q)


Undistort = Callable[[np.ndarray], np.ndarray]
"""Maps (n, 2) pixel coordinates of the camera's (distorted) image to the pinhole image."""


def _pinhole(points: np.ndarray, undistort: Undistort | None) -> np.ndarray:
    return points if undistort is None or not len(points) else np.asarray(undistort(points), np.float64)


def _centres(boxes: np.ndarray, undistort: Undistort | None) -> np.ndarray:
    """(n, 2) box centres in the pinhole image."""
    return _pinhole(np.stack([(boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2], 1), undistort)


def range_from_box_height(boxes: np.ndarray, classes: np.ndarray, camera: CameraConfig,
                          undistort: Undistort | None = None) -> np.ndarray:
    """Horizontal range (m) from the box height and the class's known cone height."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    uc = (b[:, 0] + b[:, 2]) / 2
    top = _pinhole(np.stack([uc, b[:, 1]], 1), undistort)
    bottom = _pinhole(np.stack([uc, b[:, 3]], 1), undistort)
    z = camera.range_from_height(bottom[:, 1] - top[:, 1], _HEIGHTS[np.asarray(classes, dtype=np.int64)])
    bearing = camera.bearing((top[:, 0] + bottom[:, 0]) / 2) if len(b) else np.zeros(0)
    return np.asarray(z, dtype=np.float64) / np.cos(bearing)


def range_from_depth(boxes: np.ndarray, classes: np.ndarray, depth: np.ndarray, camera: CameraConfig,
                     undistort: Undistort | None = None, quantile: float = DEPTH_QUANTILE) -> np.ndarray:
    """Horizontal range (m) from the median (or ``quantile``) of the depths inside each box.

    ``camera.far`` where every finite depth in the box is at the far plane (nothing closer there);
    NaN where the box has no usable depth at all (non-finite or nearer than ``camera.near``).
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return _depth_ranges(b, classes, depth, camera, _centres(b, undistort), check_depth_quantile(quantile))


def _depth_ranges(b: np.ndarray, classes: np.ndarray, depth: np.ndarray, camera: CameraConfig,
                  centres: np.ndarray, quantile: float = DEPTH_QUANTILE) -> np.ndarray:
    """:func:`range_from_depth` of (n, 4) float boxes whose pinhole centres are already known."""
    classes = np.asarray(classes, dtype=np.int64).reshape(-1)
    h, w = depth.shape
    out = np.full(len(b), np.nan)
    pitch = math.radians(camera.pitch_deg)
    sx, sy = w / camera.width, h / camera.height  # depth maps at another resolution than the camera
    for k, (x1, y1, x2, y2) in enumerate(b):
        bw, bh = x2 - x1, y2 - y1
        u0, u1 = int(math.floor((x1 + 0.25 * bw) * sx)), int(math.ceil((x2 - 0.25 * bw) * sx))
        v0, v1 = int(math.floor((y1 + 0.2 * bh) * sy)), int(math.ceil((y2 - 0.2 * bh) * sy))
        u0, v0 = max(0, u0), max(0, v0)
        u1, v1 = min(w, max(u1, u0 + 1)), min(h, max(v1, v0 + 1))
        patch = depth[v0:v1, u0:u1]
        finite = np.isfinite(patch) & (patch > camera.near)
        beyond = finite & (patch >= camera.far * 0.999)
        valid = patch[finite & ~beyond]
        if valid.size == 0:
            if beyond.any():
                out[k] = camera.far
            continue
        # the default keeps np.median itself: the same bytes as before the option existed
        z = float(np.median(valid) if quantile == 0.5 else np.quantile(valid, quantile))
        u, v = centres[k]
        xc = (u - camera.cx) / camera.fx * z  # right
        yc = (v - camera.cy) / camera.fy * z  # down
        forward = z * math.cos(pitch) - yc * math.sin(pitch)
        out[k] = math.hypot(forward, xc) + _MEAN_RADIUS[classes[k]]
    return out


def detections_to_cones(detections: Any, camera: CameraConfig, depth: np.ndarray | None = None,
                        undistort: Undistort | None = None,
                        depth_quantile: float = DEPTH_QUANTILE) -> dict[str, np.ndarray]:
    """Cones from detections: ``classes``, ``scores``, ``boxes`` (xyxy px), ``bearings`` (rad),
    ``ranges`` (m) and ``ranges_source`` ("depth", "far" or "height" per cone; see the module doc).

    ``detections`` is a ``Detections`` or a dict with ``boxes``, ``scores``, ``classes``; ``depth``
    an optional (H, W) metric z-depth map of the same frame; ``undistort`` the lens's inverse
    (``CameraPipeline.undistort_points``) when the frame comes through a distorting camera model;
    ``depth_quantile`` the quantile of the depths inside a box that gives its range (module doc).
    """
    depth_quantile = check_depth_quantile(depth_quantile)
    d = detections.to_dict() if hasattr(detections, "to_dict") and not isinstance(detections, dict) else detections
    boxes = np.asarray(d["boxes"], dtype=np.float64).reshape(-1, 4)
    n = boxes.shape[0]
    classes = np.asarray(d["classes"], dtype=np.int64).reshape(n)
    scores = np.asarray(d["scores"], dtype=np.float64).reshape(n)
    if n and (classes.min() < 0 or classes.max() >= len(CONE_CLASSES)):
        raise InputError(f"detection classes must be in 0..{len(CONE_CLASSES) - 1}, got {np.unique(classes).tolist()}")
    centres = _centres(boxes, undistort)  # one lens inverse for the bearings and the depth's direction
    bearings = np.asarray(camera.bearing(centres[:, 0]), dtype=np.float64).reshape(n) if n else np.zeros(0)
    ranges = np.full(n, np.nan)
    source = np.full(n, "height", dtype=object)
    if depth is not None and n:
        depth = np.asarray(depth)
        if depth.ndim != 2:
            raise InputError(f"depth must be an (H, W) array of metres, got shape {depth.shape}")
        ranges = _depth_ranges(boxes, classes, depth, camera, centres, depth_quantile)
        source[np.isfinite(ranges)] = "depth"
        source[ranges == camera.far] = "far"
    missing = ~np.isfinite(ranges)
    if missing.any():
        ranges[missing] = range_from_box_height(boxes[missing], classes[missing], camera, undistort)
    return {
        "classes": classes,
        "scores": scores,
        "boxes": boxes,
        "bearings": bearings,
        "ranges": ranges,
        "ranges_source": source.astype(str),
    }


def cones_to_observation(cones: dict[str, np.ndarray], camera: CameraConfig,
                         max_cones: int = DEFAULT_MAX_CONES) -> tuple[np.ndarray, np.ndarray]:
    """Pack ``detections_to_cones`` output into the fixed-size ``(cones, mask)`` pair."""
    return pack_cones(classes=cones["classes"], ranges=cones["ranges"], bearings=cones["bearings"],
                      scores=cones["scores"], boxes=cones["boxes"], camera=camera, max_cones=max_cones)
