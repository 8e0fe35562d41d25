"""Overlays on camera frames: detection boxes from a cone list, a top-down map inset, a text HUD.

Example:
    >>> import numpy as np
    >>> from weather_gym.camera.config import CameraConfig
    >>> from weather_gym.perception.cones import pack_cones
    >>> from weather_gym.viz.overlay import cone_list_boxes
    >>> cam = CameraConfig()
    >>> cones, mask = pack_cones(classes=np.array([1]), ranges=np.array([8.0]), bearings=np.array([0.0]),
    ...                          scores=np.array([0.7]), boxes=np.array([[330, 180, 342, 205.]]), camera=cam)
    >>> cone_list_boxes(cones, mask, cam.width, cam.height)["boxes"].round().tolist()
    [[330.0, 180.0, 342.0, 205.0]]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import cv2
import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import FIELD
from weather_gym.perception.draw import BOX_RGB, draw_detections

__all__ = ["TopDownView", "cone_list_boxes", "draw_boxes", "compose_frame"]

_CLASS_RGB = np.array([BOX_RGB[c] for c in CONE_CLASSES], dtype=np.uint8)


def cone_list_boxes(cones: np.ndarray, mask: np.ndarray, width: int, height: int) -> dict[str, np.ndarray]:
    """Pixel boxes, scores and classes of the valid rows of a cone-list observation."""
    rows = np.asarray(cones)[np.asarray(mask).astype(bool)]
    boxes = np.c_[rows[:, FIELD["x1"]] * width, rows[:, FIELD["y1"]] * height,
                  rows[:, FIELD["x2"]] * width, rows[:, FIELD["y2"]] * height]
    classes = rows[:, : len(CONE_CLASSES)].argmax(axis=1) if len(rows) else np.zeros(0, np.int64)
    return {"boxes": boxes.reshape(-1, 4), "scores": rows[:, FIELD["score"]], "classes": classes}


def draw_boxes(image: np.ndarray, boxes: dict[str, np.ndarray], *, labels: bool = True) -> np.ndarray:
    """A copy of ``image`` with the boxes (``boxes``, ``scores``, ``classes``) drawn."""
    return draw_detections(image, boxes, labels=labels, thickness=1)


class TopDownView:
    """A fixed top-down window onto the world (x right, y up), drawn with OpenCV.

    Args:
        bounds: ``(xmin, xmax, ymin, ymax)`` in metres (a margin is added).
        size: the longer side of the inset in pixels.
    """

    def __init__(self, bounds: Sequence[float], size: int = 200, margin: float = 3.0) -> None:
        xmin, xmax, ymin, ymax = (float(v) for v in bounds)
        if not (xmax > xmin and ymax > ymin) or not all(map(math.isfinite, (xmin, xmax, ymin, ymax))):
            raise InputError(f"TopDownView bounds must be finite (xmin < xmax, ymin < ymax), got {tuple(bounds)}")
        xmin, xmax, ymin, ymax = xmin - margin, xmax + margin, ymin - margin, ymax + margin
        self.scale = (size - 1) / max(xmax - xmin, ymax - ymin)
        self.width = max(int(round((xmax - xmin) * self.scale)) + 1, 8)
        self.height = max(int(round((ymax - ymin) * self.scale)) + 1, 8)
        self.origin = (xmin, ymax)

    @classmethod
    def around(cls, points: np.ndarray, size: int = 200, margin: float = 3.0) -> TopDownView:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if not len(p):
            raise InputError("TopDownView.around needs at least one point")
        lo, hi = p.min(axis=0), p.max(axis=0)
        hi = np.maximum(hi, lo + 1.0)
        return cls((lo[0], hi[0], lo[1], hi[1]), size=size, margin=margin)

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        u = (p[:, 0] - self.origin[0]) * self.scale
        v = (self.origin[1] - p[:, 1]) * self.scale
        return cast(np.ndarray, np.round(np.c_[u, v]).astype(np.int32))

    def draw(self, *, cones_xy: np.ndarray | None = None, classes: np.ndarray | None = None,
             faint_xy: np.ndarray | None = None, path: np.ndarray | None = None,
             trajectory: np.ndarray | None = None, pose: Sequence[float] | np.ndarray | None = None) -> np.ndarray:
        """RGB inset: faint reference cones, trajectory (white), cones by colour, path (green), car."""
        img = np.full((self.height, self.width, 3), 30, np.uint8)
        if faint_xy is not None and len(faint_xy):
            for u, v in self.to_px(faint_xy):
                cv2.circle(img, (int(u), int(v)), 1, (90, 90, 90), -1)
        if trajectory is not None and len(trajectory) > 1:
            cv2.polylines(img, [self.to_px(trajectory).reshape(-1, 1, 2)], False, (200, 200, 200), 1, cv2.LINE_AA)
        if cones_xy is not None and len(cones_xy):
            cls = np.zeros(len(cones_xy), np.int64) if classes is None else np.asarray(classes, np.int64)
            for (u, v), c in zip(self.to_px(cones_xy), cls):
                cv2.circle(img, (int(u), int(v)), 2, tuple(int(x) for x in _CLASS_RGB[int(c)]), -1)
        if path is not None and len(path) > 1:
            cv2.polylines(img, [self.to_px(path).reshape(-1, 1, 2)], False, (60, 230, 60), 1, cv2.LINE_AA)
        if pose is not None:
            x, y, yaw = (float(v) for v in pose[:3])
            c, s = math.cos(yaw), math.sin(yaw)
            tri = np.array([[2.6, 0.0], [-0.6, 1.0], [-0.6, -1.0]])  # car outline, metres, enlarged
            k = max(1.0, 5.0 / (self.scale * 2.6))  # at least ~5 px long
            pts = np.c_[x + k * (c * tri[:, 0] - s * tri[:, 1]), y + k * (s * tri[:, 0] + c * tri[:, 1])]
            cv2.fillPoly(img, [self.to_px(pts).reshape(-1, 1, 2)], (255, 60, 60), cv2.LINE_AA)
        return img


def compose_frame(image: np.ndarray, inset: np.ndarray | None = None, hud: Sequence[str] = ()) -> np.ndarray:
    """The camera image with the inset in the top-right corner and HUD lines at the bottom left."""
    out = np.ascontiguousarray(image).copy()
    h, w = out.shape[:2]
    if inset is not None:
        ih, iw = inset.shape[:2]
        limit = max(int(0.45 * min(h, w)), 16)
        if max(ih, iw) > limit:  # shrink to fit
            f = limit / max(ih, iw)
            inset = cv2.resize(inset, (max(int(iw * f), 1), max(int(ih * f), 1)), interpolation=cv2.INTER_AREA)
            ih, iw = inset.shape[:2]
        x0, y0 = w - iw - 4, 4
        out[y0 : y0 + ih, x0 : x0 + iw] = inset
        cv2.rectangle(out, (x0 - 1, y0 - 1), (x0 + iw, y0 + ih), (220, 220, 220), 1)
    scale = max(0.35, min(h, w) / 800.0)
    line_h = int(22 * scale) + 4
    for i, text in enumerate(reversed(list(hud))):
        y = h - 6 - i * line_h
        (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
        cv2.rectangle(out, (2, y - th - 3), (8 + tw, y + 3), (0, 0, 0), -1)
        cv2.putText(out, text, (5, y), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return out
