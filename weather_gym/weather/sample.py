"""A synthetic cone-track frame with depth, for tests, benchmarks and pictures without the simulator.

Sky gradient, grass, textured asphalt in perspective, and blue/yellow cones on both track edges,
smaller with distance; the depth map follows the same flat-ground geometry. Not a rendering of
the simulator: only a stand-in with realistic structure (edges, flat areas, small objects).

Example:
    >>> from weather_gym.weather.sample import sample_frame
    >>> img, depth = sample_frame(188, 336, seed=1)
    >>> img.shape, img.dtype.name, depth.shape, depth.dtype.name
    ((188, 336, 3), 'uint8', (188, 336), 'float32')
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["sample_frame"]

_BLUE, _YELLOW, _ORANGE = (20, 60, 200), (235, 200, 20), (245, 120, 20)


def sample_frame(h: int = 376, w: int = 672, seed: int = 0, camera_height_m: float = 1.0,
                 far_m: float = 80.0) -> tuple[np.ndarray, np.ndarray]:
    """``(image uint8 H x W x 3 RGB, depth float32 H x W metres)`` of a synthetic track scene."""
    rng = np.random.default_rng(seed)
    horizon = int(0.45 * h)
    fx = 0.5 * w  # 90 degree horizontal field of view
    img = np.empty((h, w, 3), np.float32)
    t = np.linspace(0.0, 1.0, max(horizon, 1))[:, None]
    img[:horizon] = ((1 - t) * np.array([120, 160, 215]) + t * np.array([200, 215, 230]))[:, None, :]
    img[horizon:] = (70, 125, 60)  # grass

    rows = np.arange(horizon, h) + 0.5 - horizon
    z = np.minimum(fx * camera_height_m / np.maximum(rows, 1e-3), far_m)
    depth = np.full((h, w), far_m, np.float32)
    depth[horizon:] = z[:, None]
    half_width_m = 2.5
    cx = w / 2 + rng.uniform(-0.05, 0.05) * w
    for i, (r, zz) in enumerate(zip(range(horizon, h), z, strict=True)):
        half = half_width_m * fx / zz
        x0, x1 = int(max(cx - half, 0)), int(min(cx + half, w))
        if x0 < x1:
            img[r, x0:x1] = (95, 95, 100)
        if i % 2 == 0 and x0 < x1:  # lane texture
            img[r, x0:x1] += rng.normal(0, 6, size=(x1 - x0, 1))
    img = np.clip(img + rng.normal(0, 3, size=img.shape), 0, 255).astype(np.uint8)

    for zz in np.geomspace(3.0, 40.0, 9)[::-1]:  # far cones first, near ones drawn over them
        row = horizon + fx * camera_height_m / zz
        if row >= h:
            continue
        size = max(0.33 * fx / zz, 1.0)  # a 33 cm cone
        for side, color in ((-1, _BLUE), (1, _YELLOW)):
            x = cx + side * half_width_m * fx / zz
            base_y = int(row)
            top = (int(x), int(base_y - size))
            pts = np.array([[int(x - size / 3), base_y], [int(x + size / 3), base_y], top], np.int32)
            cv2.fillConvexPoly(img, pts, color, cv2.LINE_AA)
            stripe_y = int(base_y - size * 0.5)
            cv2.line(img, (int(x - size / 6), stripe_y), (int(x + size / 6), stripe_y), (240, 240, 240),
                     max(int(size / 10), 1))
            mask = np.zeros((h, w), np.uint8)
            cv2.fillConvexPoly(mask, pts, 1)
            depth[mask.astype(bool)] = zz
    big = (int(cx + 0.4 * fx / 8), int(horizon + fx * camera_height_m / 8))
    if big[1] < h:
        size = int(0.5 * fx / 8)
        cv2.fillConvexPoly(img, np.array([[big[0] - size // 3, big[1]], [big[0] + size // 3, big[1]],
                                          [big[0], big[1] - size]], np.int32), _ORANGE, cv2.LINE_AA)
    return img, depth
