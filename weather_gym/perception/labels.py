"""Label conventions shared by datasets, training and scoring (no heavy imports).

A cone whose visible box is shorter than ``MIN_BOX_HEIGHT_PX`` pixels (in the original camera
image) is a *tiny* cone: it is written with ``iscrowd = 1``, it is neither a positive nor a negative
in training, and pycocotools ignores it in scoring (a detection on it is neither a hit nor a false
positive). At the default camera (672x376, 90 deg HFOV, fx = 336 px) an upright 325 mm cone is
8 px tall at about 13.6 m.

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.labels import tiny_mask, MIN_BOX_HEIGHT_PX
    >>> tiny_mask(np.array([[0, 0, 5, 7.0], [0, 0, 5, 8.0]])).tolist(), MIN_BOX_HEIGHT_PX
    ([True, False], 8.0)
"""

from __future__ import annotations

import numpy as np

from weather_gym.cone_spec import CONE_CLASSES

MIN_BOX_HEIGHT_PX: float = 8.0
"""Boxes shorter than this (pixels, original image) are ``iscrowd`` / ignored."""

CATEGORIES: list[dict] = [{"id": i + 1, "name": n, "supercategory": "cone"} for i, n in enumerate(CONE_CLASSES)]
"""COCO categories: id = class id + 1."""


def tiny_mask(boxes_xyxy: np.ndarray, min_height: float = MIN_BOX_HEIGHT_PX) -> np.ndarray:
    """True for boxes (K, 4 xyxy) whose height is below ``min_height`` pixels."""
    b = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    return (b[:, 3] - b[:, 1]) < float(min_height)


def xyxy_to_xywh(boxes: np.ndarray) -> np.ndarray:
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return np.c_[b[:, :2], b[:, 2:] - b[:, :2]]


def xywh_to_xyxy(boxes: np.ndarray) -> np.ndarray:
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return np.c_[b[:, :2], b[:, :2] + b[:, 2:]]
