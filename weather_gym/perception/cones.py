"""The fixed-size cone-list observation that perception hands to mapping and control.

A cone list is an ``(N, len(CONE_FIELDS))`` float32 array padded with zeros plus an int8 ``mask``
of valid rows, so stable-baselines3 and vectorized envs accept it.

Example:
    >>> import numpy as np
    >>> from weather_gym.camera.config import CameraConfig
    >>> from weather_gym.perception.cones import pack_cones, CONE_FIELDS
    >>> cones, mask = pack_cones(classes=np.array([0]), ranges=np.array([5.0]), bearings=np.array([0.1]),
    ...                          scores=np.array([0.9]), boxes=np.array([[300, 180, 320, 210.]]),
    ...                          camera=CameraConfig(), max_cones=4)
    >>> cones.shape, mask.tolist(), CONE_FIELDS[4]
    ((4, 14), [1, 0, 0, 0], 'range')
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import CONE_CLASSES, UNKNOWN_CLASS
from weather_gym.core.errors import InputError

CONE_FIELDS: tuple[str, ...] = (
    *(f"is_{c}" for c in CONE_CLASSES),  # one-hot class (4); all zero: colour unknown (a LiDAR's cone)
    "range",  # horizontal distance camera -> cone, metres
    "bearing",  # horizontal angle from the optical axis, rad, positive left
    "score",  # detector confidence in [0, 1] (1 for ground truth)
    "x1", "y1", "x2", "y2",  # box, normalised by image width/height
    "x_body", "y_body",  # cone position in the car frame (origin at the car reference point), metres
    "size_px",  # box height in pixels
)
FIELD = {name: i for i, name in enumerate(CONE_FIELDS)}
DEFAULT_MAX_CONES = 64

_BOX_FIELDS = slice(FIELD["x1"], FIELD["y2"] + 1)


def cone_list_space(max_cones: int = DEFAULT_MAX_CONES) -> spaces.Dict:
    """Gymnasium space of ``{"cones", "mask"}`` (state is added by the wrapper that passes it through)."""
    return spaces.Dict(
        {
            "cones": spaces.Box(-np.inf, np.inf, (max_cones, len(CONE_FIELDS)), np.float32),
            "mask": spaces.Box(0, 1, (max_cones,), np.int8),
        }
    )


def body_xy(ranges: np.ndarray, bearings: np.ndarray, camera: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Car-frame (x forward, y left) position of cones seen by ``camera`` at ``ranges``/``bearings``."""
    x = camera.mount_x + ranges * np.cos(bearings)
    y = ranges * np.sin(bearings)
    return x, y


def pack_cones(
    *,
    classes: np.ndarray,
    ranges: np.ndarray,
    bearings: np.ndarray,
    scores: np.ndarray,
    boxes: np.ndarray,
    camera: CameraConfig,
    max_cones: int = DEFAULT_MAX_CONES,
) -> tuple[np.ndarray, np.ndarray]:
    """Pack per-cone arrays into the padded ``(cones, mask)`` pair.

    When there are more than ``max_cones`` cones the nearest ones are kept (they matter most for
    control). Boxes are ``xyxy`` pixels.
    """
    classes = np.asarray(classes, dtype=np.int64).reshape(-1)
    n = classes.shape[0]
    ranges = np.asarray(ranges, dtype=np.float64).reshape(n)
    bearings = np.asarray(bearings, dtype=np.float64).reshape(n)
    scores = np.asarray(scores, dtype=np.float64).reshape(n)
    boxes = np.asarray(boxes, dtype=np.float64).reshape(n, 4)
    if n and (classes.min() < UNKNOWN_CLASS or classes.max() >= len(CONE_CLASSES)):
        raise InputError(f"cone classes must be in 0..{len(CONE_CLASSES) - 1} or {UNKNOWN_CLASS} (unknown colour), "
                         f"got {np.unique(classes).tolist()}")
    order = np.argsort(ranges, kind="stable")[:max_cones]
    k = order.shape[0]
    out = np.zeros((max_cones, len(CONE_FIELDS)), dtype=np.float32)
    mask = np.zeros((max_cones,), dtype=np.int8)
    if k:
        c = classes[order]
        r, br, b = ranges[order], bearings[order], boxes[order]
        known = c >= 0  # an unknown colour leaves the one-hot all zero
        out[np.flatnonzero(known), c[known]] = 1.0
        out[:k, FIELD["range"]] = r
        out[:k, FIELD["bearing"]] = br
        out[:k, FIELD["score"]] = scores[order]
        out[:k, _BOX_FIELDS] = b / np.array([camera.width, camera.height, camera.width, camera.height], np.float64)
        xb, yb = body_xy(r, br, camera)
        out[:k, FIELD["x_body"]] = xb
        out[:k, FIELD["y_body"]] = yb
        out[:k, FIELD["size_px"]] = b[:, 3] - b[:, 1]
        mask[:k] = 1
    return out, mask


def unpack_cones(cones: np.ndarray, mask: np.ndarray) -> dict[str, np.ndarray]:
    """Valid rows as named arrays: ``classes`` (:data:`~weather_gym.core.cone_spec.UNKNOWN_CLASS` where the
    one-hot is all zero), ``range``, ``bearing``, ``score``, ``x_body``, ``y_body``."""
    valid = np.asarray(mask).astype(bool)
    rows = np.asarray(cones)[valid]
    onehot = rows[:, : len(CONE_CLASSES)]
    return {
        "classes": (np.where(onehot.max(axis=1) > 0, onehot.argmax(axis=1), UNKNOWN_CLASS) if len(rows)
                    else np.zeros(0, np.int64)),
        "range": rows[:, FIELD["range"]],
        "bearing": rows[:, FIELD["bearing"]],
        "score": rows[:, FIELD["score"]],
        "x_body": rows[:, FIELD["x_body"]],
        "y_body": rows[:, FIELD["y_body"]],
        "size_px": rows[:, FIELD["size_px"]],
    }
