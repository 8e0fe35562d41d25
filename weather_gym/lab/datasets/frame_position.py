"""Where in the frame a set's cones are: the share of them near the frame's edge.

A cone is *near the edge* when its box centre lies beyond ``EDGE_RADIUS`` of the frame's half-diagonal
ellipse, ``hypot((x - w/2) / (w/2), (y - h/2) / (h/2)) > EDGE_RADIUS``: the corners and the far left
and right. At low light the detector loses those cones first, so a set's relative mAP at the
low-light presets falls with its edge share (docs/calibration.md, "Why low light spreads over tracks").

Example:
    >>> import numpy as np
    >>> edge_radius(np.array([[326.0, 178, 20, 20], [0, 0, 20, 20]]), 672, 376).round(2)
    array([0.  , 1.36])
    >>> from weather_gym.lab.datasets.coco import load_coco  # doctest: +SKIP
    >>> edge_share(load_coco("scratch/calib/held240_b_shape"))  # doctest: +SKIP
    (528, 1876)
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

__all__ = ["EDGE_CLASSES", "EDGE_RADIUS", "edge_radius", "edge_share"]

EDGE_RADIUS = 0.8
"""Normalised radius (of the frame's half-diagonal ellipse) beyond which a box centre is near the edge."""
EDGE_CLASSES = ("blue", "yellow")
"""The classes counted: the track's boundary cones, the metric the low-light presets were calibrated on."""


def edge_radius(boxes_xywh: np.ndarray, width, height) -> np.ndarray:
    """Normalised radius of each COCO ``[x, y, w, h]`` box centre: 0 at the frame's centre, 1 on the
    ellipse through the middles of its sides, about 1.41 in its corners (``width``, ``height``: the
    frame's size, one for all boxes or one per box)."""
    b = np.asarray(boxes_xywh, dtype=np.float64).reshape(-1, 4)
    cx = (b[:, 0] + b[:, 2] / 2) / (np.asarray(width) / 2) - 1.0
    cy = (b[:, 1] + b[:, 3] / 2) / (np.asarray(height) / 2) - 1.0
    return np.hypot(cx, cy)


def _stored_scored(a: dict) -> bool:
    """Scored by the dataset's own flags: neither an ignore region nor flagged too small (``iscrowd``)."""
    return not a.get("iscrowd") and not a.get("ignore")


def edge_share(ds, classes: Iterable[str] = EDGE_CLASSES, radius: float = EDGE_RADIUS,
               scored: Callable[[dict], bool] = _stored_scored) -> tuple[int, int]:
    """``(near the edge, all)`` of a ``CocoDataset``'s scored cones of ``classes``; ``scored`` tells
    a scored annotation (default: the dataset's stored flags)."""
    names = {c["id"]: c["name"] for c in ds.data["categories"]}
    wanted = set(classes)
    sizes = {im["id"]: (im["width"], im["height"]) for im in ds.images}
    anns = [a for a in ds.data["annotations"] if names.get(a["category_id"]) in wanted and scored(a)]
    if not anns:
        return 0, 0
    wh = np.array([sizes[a["image_id"]] for a in anns], dtype=np.float64)
    r = edge_radius(np.array([a["bbox"] for a in anns]), wh[:, 0], wh[:, 1])
    return int((r > radius).sum()), len(anns)
