"""Vignetting: the image darkens towards its corners (lens fall-off, a dirty lens hood).

**Meaning of k**: the fraction of light lost in the corners. Linear light is multiplied by
``1 - k * (r / r_max) ** exponent`` (``r`` distance from the centre ``(center_x, center_y)`` in
image fractions, ``r_max`` the half-diagonal); on 8-bit values that is a gain of that to the power
1/2.2. The gain map is cached per image size and k.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> out = make("vignette", k=0.8)(np.full((50, 80, 3), 200, np.uint8))
    >>> int(out[25, 40, 0]), int(out[0, 0, 0]) < 150
    (200, True)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather._common import into, readonly
from weather_gym.weather.base import KnobEffect
from weather_gym.weather.registry import register_effect

__all__ = ["Vignette"]


@lru_cache(maxsize=16)
def _gain_map(h: int, w: int, k: float, exponent: float, cx: float, cy: float) -> np.ndarray:
    y = (np.arange(h, dtype=np.float64) + 0.5) / h - cy
    x = (np.arange(w, dtype=np.float64) + 0.5) / w - cx
    r = np.hypot(x[None, :] * w, y[:, None] * h) / (0.5 * np.hypot(w, h))
    gain = np.clip(1.0 - k * np.minimum(r, 1.0) ** exponent, 0.0, 1.0) ** (1 / 2.2)
    g8 = np.rint(255.0 * gain).astype(np.uint8)
    return readonly(cv2.cvtColor(g8, cv2.COLOR_GRAY2RGB))


@register_effect
@dataclass(frozen=True)
class Vignette(KnobEffect):
    """Corner darkening; ``k`` = light lost in the corners. See module doc."""

    name: ClassVar[str] = "vignette"
    CHAIN_RANK: ClassVar[float] = 70
    NOMINAL_NOUN: ClassVar[str] = "vignetting"

    exponent: float = 2.0
    center_x: float = 0.5
    center_y: float = 0.5

    PARAM_BOUNDS: ClassVar = {"exponent": (0.5, 8.0)}
    PARAM_LIMITS: ClassVar = {"center_x": (0.0, 1.0), "center_y": (0.0, 1.0)}

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        h, w = img.shape[:2]
        g = _gain_map(h, w, self.k, self.exponent, self.center_x, self.center_y)
        into(cv2.multiply(img, g, dst=out, scale=1 / 255), out)
