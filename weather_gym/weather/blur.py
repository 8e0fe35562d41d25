"""Defocus blur (out-of-focus lens, a film of water or dirt that scatters light).

**Meaning of k**: the blur radius as a fraction of ``max_radius_frac`` of the image width:
``radius = k * max_radius_frac * W`` pixels (6.7 px at k = 1 and 672 px width), so the same k
blurs cones the same at any resolution. The disk-shaped defocus PSF is approximated by a
Gaussian-like blur of the same second moment (``sigma = radius / 2``): OpenCV's fast 3x3 and 5x5
box passes whose variances add up to ``sigma**2`` (the rest a fraction of one more pass, so that
the output changes continuously with k), at half resolution for large blurs
(:func:`~weather_gym.weather._common.smooth`).

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.zeros((40, 60, 3), np.uint8); img[20, 30] = 255
    >>> int(make("blur", k=1.0, max_radius_frac=0.05)(img)[20, 30, 0]) < 255
    True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from weather_gym.weather._common import smooth
from weather_gym.weather.base import KnobEffect
from weather_gym.weather.registry import register_effect

__all__ = ["Blur"]


@register_effect
@dataclass(frozen=True)
class Blur(KnobEffect):
    """Defocus; ``k`` scales the blur radius up to ``max_radius_frac`` of the width."""

    name: ClassVar[str] = "blur"
    CHAIN_RANK: ClassVar[float] = 50
    NOMINAL_NOUN: ClassVar[str] = "defocus blur"

    max_radius_frac: float = 0.01

    PARAM_BOUNDS: ClassVar = {"max_radius_frac": (0.001, 0.05)}

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        smooth(img, 0.5 * self.k * self.max_radius_frac * img.shape[1], out, exact=True)
