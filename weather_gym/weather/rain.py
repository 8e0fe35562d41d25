"""Falling rain: bright slanted streaks in front of the camera and a veil of scattered light.

**Meaning of k**: the rain rate. The number of streaks per frame is Poisson with mean
``k * density`` per 10,000 pixels, and the veil (light scattered by the rain, which lowers
contrast) has weight ``k * haze``. Streaks are antialiased lines of ``length_frac`` of the image
height (random 0.5x to 1.5x), slanted by ``slant_deg``, blended with opacity ``streak_alpha``
towards the gray level ``brightness * 255``; a new set falls every frame.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> out = make("rain", k=1.0)(np.zeros((120, 160, 3), np.uint8), rng=np.random.default_rng(0))
    >>> int(out.max()) > int(np.median(out))       # streaks brighter than the veil
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather._common import blend_into, blend_terms
from weather_gym.weather.base import KnobEffect
from weather_gym.weather.registry import register_effect

__all__ = ["Rain"]


@register_effect
@dataclass(frozen=True)
class Rain(KnobEffect):
    """Rain streaks and veil; ``k`` = rain rate. See module doc."""

    name: ClassVar[str] = "rain"
    CHAIN_RANK: ClassVar[float] = 20
    NOMINAL_NOUN: ClassVar[str] = "rain"

    density: float = 3.0
    length_frac: float = 0.06
    slant_deg: float = 10.0
    streak_alpha: float = 0.45
    brightness: float = 0.8
    haze: float = 0.2
    thickness: int = 1

    PARAM_BOUNDS: ClassVar = {
        "density": (0.1, 30.0),
        "length_frac": (0.005, 0.3),
        "streak_alpha": (0.05, 1.0),
        "haze": (0.0, 0.8),
    }
    PARAM_LIMITS: ClassVar = {"slant_deg": (-60.0, 60.0), "brightness": (0.0, 1.0), "thickness": (1, 10)}

    def _sample_frame(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any) -> Any:
        """The frame's streaks: an ``(n, 2, 1, 2)`` int32 array of segment ends (pixels)."""
        h, w = shape[:2]
        n = int(rng.poisson(self.k * self.density * h * w / 1e4))
        if n == 0:
            return np.empty((0, 2, 1, 2), np.int32)
        length = self.length_frac * h * rng.uniform(0.5, 1.5, size=n)
        a = math.radians(self.slant_deg)
        dx, dy = length * math.sin(a), length * math.cos(a)
        x0 = rng.uniform(min(-dx.max(), 0), w + max(-dx.min(), 0), size=n)
        y0 = rng.uniform(-dy.max(), h, size=n)
        seg = np.stack([np.stack([x0, y0], 1), np.stack([x0 + dx, y0 + dy], 1)], 1)
        return np.rint(seg).astype(np.int32).reshape(n, 2, 1, 2)

    def streak_mask(self, h: int, w: int, segments: np.ndarray) -> np.ndarray:
        """uint8 ``H x W`` streak mask (255 = fully covered) of the drawn ``segments``."""
        mask = np.zeros((h, w), np.uint8)
        if len(segments):
            cv2.polylines(mask, list(segments), False, 255, self.thickness, cv2.LINE_AA)
        return mask

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        h, w = img.shape[:2]
        veil = self.k * self.haze
        w8 = cv2.convertScaleAbs(self.streak_mask(h, w, draw), alpha=self.streak_alpha * (1 - veil), beta=255 * veil)
        blend_into(img, blend_terms(w8, 255.0 * self.brightness), out)
