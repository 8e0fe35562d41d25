"""Glare: a low sun in or near the frame — flare, veiling glare and bloom around bright areas.

**Meaning of k**: the strength of the stray light. The image is blended towards warm white with a
per-pixel weight ``k * (flare + veil + bloom)``:

* ``flare``: a bright core (``radius_frac`` of the diagonal) with a halo at the source
  ``(source_x, source_y)`` (image fractions; outside [0, 1] is a sun just out of frame), and
  ``ghosts`` faint ghost discs on the line from the source through the image centre;
* ``veil``: uniform veiling glare, the contrast loss of light scattered in the lens;
* ``bloom``: light spread (Gaussian, ``bloom_spread`` of the width) from the frame's own bright
  areas (above ``bloom_threshold``).

The flare weights are cached per image size and k; bloom is computed at quarter resolution, all
weights in 8 bits.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> out = make("glare", k=1.0)(np.zeros((90, 160, 3), np.uint8))
    >>> int(out[9, 128].min()) > int(out[80, 20].max())  # bright at the source, dimmer far away
    True
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather._common import blend_into, blend_terms, readonly, smooth
from weather_gym.weather.base import KnobEffect
from weather_gym.weather.registry import register_effect

__all__ = ["Glare"]

_WARM_WHITE = (255, 244, 224)


@lru_cache(maxsize=16)
def flare_pattern(h: int, w: int, sx: float, sy: float, radius_frac: float, ghosts: int) -> np.ndarray:
    """Float32 ``H x W`` flare intensity in [0, 1] (core, halo, ghosts)."""
    r = max(radius_frac * np.hypot(w, h), 1.0)
    px, py = sx * w, sy * h
    x = np.arange(w, dtype=np.float32)[None, :] - px
    y = np.arange(h, dtype=np.float32)[:, None] - py
    d2 = (x * x + y * y) / np.float32(r * r)
    pattern = np.exp(-d2) + 0.35 / (1.0 + d2 / 4.0)
    canvas: np.ndarray = np.zeros((h, w), np.float32)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    for i, t in enumerate(np.linspace(0.55, 1.0, ghosts) if ghosts else []):  # 1 = mirror point
        gx, gy = px + t * 2 * (cx - px), py + t * 2 * (cy - py)
        gr = max(int(r * (0.15 + 0.1 * (i % 3))), 1)
        cv2.circle(canvas, (int(round(gx)), int(round(gy))), gr, 0.12, -1, cv2.LINE_AA)
    if ghosts:
        canvas = cv2.GaussianBlur(canvas, (0, 0), max(r * 0.05, 0.5))
    return readonly(np.clip(pattern + canvas, 0.0, 1.0).astype(np.float32))


@lru_cache(maxsize=16)
def _flare_weights(h: int, w: int, sx: float, sy: float, radius_frac: float, ghosts: int, veil: float,
                   k: float) -> np.ndarray:
    """uint8 ``255 k (flare + veil)`` (saturated), single channel."""
    pattern = flare_pattern(h, w, sx, sy, radius_frac, ghosts)
    return readonly(cv2.convertScaleAbs(pattern, alpha=255.0 * k, beta=255.0 * k * veil))


@lru_cache(maxsize=16)
def _flare_terms(h: int, w: int, sx: float, sy: float, radius_frac: float, ghosts: int, veil: float,
                 k: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`blend_terms` of the flare alone (no bloom), cached."""
    w1 = _flare_weights(h, w, sx, sy, radius_frac, ghosts, veil, k)
    a, b = blend_terms(w1, _WARM_WHITE)
    return readonly(a), readonly(b)


@register_effect
@dataclass(frozen=True)
class Glare(KnobEffect):
    """Sun flare, veiling glare and bloom; ``k`` = stray-light strength. See module doc."""

    name: ClassVar[str] = "glare"
    CHAIN_RANK: ClassVar[float] = 30
    NOMINAL_NOUN: ClassVar[str] = "sun glare"

    source_x: float = 0.8
    source_y: float = 0.1
    radius_frac: float = 0.12
    veil: float = 0.15
    ghosts: int = 4
    bloom: float = 0.3
    bloom_threshold: float = 0.85
    bloom_spread: float = 0.04

    PARAM_BOUNDS: ClassVar = {"radius_frac": (0.01, 0.5), "veil": (0.0, 0.6), "bloom": (0.0, 1.0)}
    PARAM_LIMITS: ClassVar = {
        "source_x": (-1.0, 2.0),
        "source_y": (-1.0, 2.0),
        "ghosts": (0, 12),
        "bloom_threshold": (0.0, 1.0),
        "bloom_spread": (0.005, 0.3),
    }

    def _bloom(self, img: np.ndarray) -> np.ndarray:
        """uint8 ``255 k bloom spread`` at full size, single channel (computed at quarter size)."""
        h, w = img.shape[:2]
        small = cv2.resize(img, (max(w // 4, 1), max(h // 4, 1)), interpolation=cv2.INTER_LINEAR)
        gray = cv2.cvtColor(small, cv2.COLOR_RGB2GRAY)
        _, bright = cv2.threshold(gray, 255 * self.bloom_threshold, 255, cv2.THRESH_TOZERO)
        spread = smooth(bright, max(self.bloom_spread * w / 4, 0.5))  # quarter resolution
        spread = cv2.convertScaleAbs(spread, alpha=self.k * self.bloom)
        return cv2.resize(spread, (w, h), interpolation=cv2.INTER_LINEAR)

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        h, w = img.shape[:2]
        flare = (h, w, self.source_x, self.source_y, self.radius_frac, self.ghosts, self.veil, self.k)
        if self.bloom > 0:
            terms = blend_terms(cv2.add(_flare_weights(*flare), self._bloom(img)), _WARM_WHITE)
        else:
            terms = _flare_terms(*flare)
        blend_into(img, terms, out)
