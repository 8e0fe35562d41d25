"""Synthetic cone frames for tests: coloured triangles on a textured background (no simulator).

Imported by the tests in this folder as ``cone_synth`` (pytest puts the folder on ``sys.path``).
"""

from __future__ import annotations

import cv2
import numpy as np

from weather_gym.core.cone_spec import CONE_BODY_RGB, CONE_CLASSES, CONE_STRIPE_RGB


def synth_frame(rng: np.random.Generator, n_cones: int = 6, size: tuple[int, int] = (672, 376)):
    """One RGB frame and its ground truth ``{"boxes" xyxy, "classes", "ranges", "bearings"}``."""
    w, h = size
    img = np.empty((h, w, 3), np.uint8)
    horizon = h // 2
    img[:horizon] = (150, 180, 220)
    noise = rng.integers(-12, 13, size=(h - horizon, w, 1))
    img[horizon:] = np.clip(np.array([95, 95, 100]) + noise, 0, 255)
    boxes, classes = [], []
    for _ in range(n_cones):
        c = int(rng.integers(0, len(CONE_CLASSES)))
        ch = int(rng.integers(14, 60))
        cw = int(ch * 0.7)
        x = int(rng.integers(0, w - cw))
        y = int(rng.integers(horizon, h - ch))
        body = tuple(int(255 * v) for v in CONE_BODY_RGB[CONE_CLASSES[c]])
        stripe = tuple(int(255 * v) for v in CONE_STRIPE_RGB[CONE_CLASSES[c]])
        pts = np.array([[x + cw // 2, y], [x, y + ch - 1], [x + cw - 1, y + ch - 1]], np.int32)
        cv2.fillPoly(img, [pts], body)
        ys = y + int(ch * 0.45)
        cv2.line(img, (x + cw // 3, ys), (x + 2 * cw // 3, ys), stripe, max(1, ch // 10))
        boxes.append([x, y, x + cw, y + ch])
        classes.append(c)
    boxes = np.array(boxes, np.float32).reshape(-1, 4)
    ranges = 336 * 0.325 / np.maximum(boxes[:, 3] - boxes[:, 1], 1)
    return img, {"boxes": boxes, "classes": np.array(classes, np.int64), "ranges": ranges.astype(np.float32),
                 "bearings": np.arctan2(336 - (boxes[:, 0] + boxes[:, 2]) / 2, 336).astype(np.float32)}


def write_synth_dataset(root, n: int, seed: int = 0):
    """A small COCO folder of synthetic frames (with a constant depth map)."""
    from weather_gym.lab.datasets.coco import CocoWriter

    rng = np.random.default_rng(seed)
    with CocoWriter(root) as w:
        for _i in range(n):
            img, gt = synth_frame(rng)
            w.add(img, {"track": "synthetic", "pose": [0.0, 0.0, 0.0], "speed": 0.0, "yaw_rate": 0.0}, gt,
                  depth=np.full(img.shape[:2], 10.0, np.float32))
    return root
