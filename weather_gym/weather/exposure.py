"""Exposure error: a camera whose auto-exposure or tone mapping gets the scene wrong.

**Meaning of k**: the exposure error as a fraction of ``max_stops``: linear light is multiplied by
``2 ** (-k * max_stops)`` (``direction="under"``) or ``2 ** (+k * max_stops)`` (``"over"``: highlights
clip), then re-encoded with a tone curve whose gamma is off by ``k * gamma_error`` (relative), whose contrast
is changed by ``k * contrast`` (positive: an S-curve, darker shadows and brighter highlights, as a
camera's tone mapping adds; negative: the inverse, flatter curve) and whose black level is lifted by
``k * flare`` (veiling flare washes out the shadows). Together these fit the common tone curves of
real cameras (gain, gamma, S-curve, lifted blacks). One look-up table per k: about as cheap as an
effect can be.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.full((4, 4, 3), 128, np.uint8)
    >>> int(make("exposure", k=1.0, max_stops=1.0)(img)[0, 0, 0])    # one stop under
    92
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar, cast

import cv2
import numpy as np

from weather_gym.weather._common import flat, into, linear_of_code, readonly, srgb_encode
from weather_gym.weather.base import KnobEffect
from weather_gym.weather.registry import register_effect

__all__ = ["Exposure", "exposure_lut"]


def s_curve(v: np.ndarray, contrast: float) -> np.ndarray:
    """Monotone contrast curve on [0, 1]: a blend with smoothstep (``contrast`` > 0) or its inverse (< 0)."""
    a = min(abs(float(contrast)), 1.0)
    if a == 0.0:
        return v
    if contrast > 0:
        s = v * v * (3.0 - 2.0 * v)
    else:
        s = 0.5 - np.sin(np.arcsin(np.clip(1.0 - 2.0 * v, -1.0, 1.0)) / 3.0)
    return cast(np.ndarray, (1.0 - a) * v + a * s)


@lru_cache(maxsize=256)
def exposure_lut(stops: float, gamma_error: float, flare: float, contrast: float = 0.0) -> np.ndarray:
    """8-bit tone curve: gain of ``stops`` in linear light, gamma off by ``gamma_error``, contrast curve
    ``contrast``, black lift ``flare``."""
    y = np.clip(linear_of_code() * 2.0 ** stops, 0.0, 1.0)
    v = s_curve(srgb_encode(y) ** (1.0 + gamma_error), contrast)
    v = flare + (1.0 - flare) * v
    return readonly(np.clip(np.rint(255.0 * v), 0, 255).astype(np.uint8))


@register_effect
@dataclass(frozen=True)
class Exposure(KnobEffect):
    """Wrong exposure; ``k`` = fraction of ``max_stops`` of error. See module doc."""

    name: ClassVar[str] = "exposure"
    CHAIN_RANK: ClassVar[float] = 90
    NOMINAL_NOUN: ClassVar[str] = "under-exposure"

    max_stops: float = 3.0
    direction: str = "under"
    gamma_error: float = 0.0
    flare: float = 0.0
    contrast: float = 0.0

    CHOICES: ClassVar = {"direction": ("under", "over")}
    PARAM_BOUNDS: ClassVar = {"max_stops": (0.25, 8.0), "gamma_error": (-0.5, 1.0), "flare": (0.0, 0.3),
                              "contrast": (-1.0, 1.0)}

    def _lut(self) -> np.ndarray:
        sign = -1.0 if self.direction == "under" else 1.0
        return exposure_lut(sign * self.k * self.max_stops, self.k * self.gamma_error, self.k * self.flare,
                            self.k * self.contrast)

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        into(cv2.LUT(flat(img), self._lut(), dst=flat(out)), flat(out))

    def _render_batch(self, imgs: np.ndarray, draws: list[Any] | None, depth: np.ndarray | None,
                      states: list[dict[str, float]]) -> np.ndarray:
        return self._render_frame(imgs, None, None, {})  # one LUT pass
