"""Ignore masks in scoring: ground truth and detections inside a masked region do not count.

An ignore mask is a boolean ``H x W`` array (True = ignored pixel), e.g. the car's own bodywork in
the lower part of an onboard camera's frame. A box counts as *inside* the mask when at least
:data:`MASKED_FRACTION` of its area is masked: such a ground-truth cone is ignored (like a tiny
cone: a detection on it is neither a hit nor a false positive) and such a detection is dropped.

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.ignore import box_mask_fraction
    >>> mask = np.zeros((10, 10), bool); mask[5:] = True          # lower half ignored
    >>> box_mask_fraction(mask, np.array([[0, 0, 4, 4], [0, 4, 4, 8], [0, 6, 4, 10.]])).round(2).tolist()
    [0.0, 0.75, 1.0]
"""

from __future__ import annotations

import numpy as np

from weather_gym.core.errors import InputError

__all__ = ["MASKED_FRACTION", "box_mask_fraction", "inside_mask", "check_mask"]

MASKED_FRACTION = 0.5
"""A box at least this much inside the ignore mask is ignored (ground truth) or dropped (detection)."""


def check_mask(mask: np.ndarray, size: tuple[int, int], where: str) -> np.ndarray:
    """``mask`` as a boolean ``(H, W)`` array; ValueError naming ``where`` unless it is ``size`` (W, H)."""
    m = np.asarray(mask)
    w, h = size
    if m.ndim != 2 or m.shape != (h, w):
        raise InputError(f"{where}: ignore mask is {_shape(m)} but the frames are {w}x{h}; "
                         "a mask must have the frames' size")
    return m.astype(bool, copy=False)


def _shape(m: np.ndarray) -> str:
    return f"{m.shape[1]}x{m.shape[0]}" if m.ndim == 2 else f"of shape {m.shape}"


def _integral(mask: np.ndarray) -> np.ndarray:
    ii = np.zeros((mask.shape[0] + 1, mask.shape[1] + 1), np.int64)
    np.cumsum(np.cumsum(mask, axis=0, dtype=np.int64), axis=1, out=ii[1:, 1:])
    return ii


def box_mask_fraction(mask: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Fraction of each xyxy box's (pixel-rounded) area that is masked; 0 for empty boxes."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    if b.shape[0] == 0:
        return np.zeros(0)
    m = np.asarray(mask, bool)
    h, w = m.shape
    ii = _integral(m)
    x1 = np.clip(np.floor(b[:, 0]), 0, w).astype(np.int64)
    y1 = np.clip(np.floor(b[:, 1]), 0, h).astype(np.int64)
    x2 = np.clip(np.ceil(b[:, 2]), 0, w).astype(np.int64)
    y2 = np.clip(np.ceil(b[:, 3]), 0, h).astype(np.int64)
    area = (x2 - x1) * (y2 - y1)
    inside = ii[y2, x2] - ii[y1, x2] - ii[y2, x1] + ii[y1, x1]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(area > 0, inside / np.maximum(area, 1), 0.0)


def inside_mask(mask: np.ndarray | None, boxes: np.ndarray) -> np.ndarray:
    """True for the boxes at least :data:`MASKED_FRACTION` inside ``mask`` (all False without a mask)."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    if mask is None:
        return np.zeros(b.shape[0], bool)
    return box_mask_fraction(mask, b) >= MASKED_FRACTION
