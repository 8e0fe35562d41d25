"""Poisson-Gaussian sensor noise (photon shot noise + read noise) at a raised sensor gain.

**Meaning of k**: the sensor gain as a fraction of ``max_gain``: ``gain = k * max_gain``. At gain
``g`` a pixel of linear value ``x`` gets noise of variance ``g * x / full_well_e +
(g * read_noise_e / full_well_e)^2`` (full scale = 1): shot noise grows with the signal, read noise
is constant. The noise is added in linear light and carried to 8-bit sRGB values through the slope
of the sRGB curve, per pixel and channel, new every frame: a Gaussian with that signal-dependent
sigma (no per-pixel Poisson draw), each value a fresh random sign times a standard-normal
magnitude (256 equiprobable levels) read from a fixed table through a window the generator moves
every frame (:func:`~weather_gym.weather._common.add_sensor_noise`): independent within a frame,
uncorrelated between frames.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.full((64, 64, 3), 128, np.uint8)
    >>> out = make("noise", k=1.0)(img, rng=np.random.default_rng(0))
    >>> 5 < float(out.std()) < 30
    True
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import ClassVar

import numpy as np

from weather_gym.weather._common import add_sensor_noise, linear_of_code, readonly, srgb_slope
from weather_gym.weather.base import KnobEffect
from weather_gym.weather.registry import register_effect

__all__ = ["Noise", "noise_sigma_lut"]


@lru_cache(maxsize=64)
def noise_sigma_lut(gain: float, full_well_e: float, read_noise_e: float, base_gain: float = 0.0) -> np.ndarray:
    """Sigma (8-bit code values) of the noise added to each code value at ``gain``.

    ``base_gain`` > 0 subtracts the variance already present at that gain (the clean frame's own).
    """
    x = linear_of_code()
    var = (gain - base_gain) * x / full_well_e + ((gain ** 2 - base_gain ** 2) * read_noise_e ** 2
                                                  / full_well_e ** 2)
    sigma = 255.0 * srgb_slope(x) * np.sqrt(np.maximum(var, 0.0))
    return readonly(sigma.astype(np.float32))


@register_effect
@dataclass(frozen=True)
class Noise(KnobEffect):
    """Sensor noise; ``k`` = gain / ``max_gain``. See module doc."""

    name: ClassVar[str] = "noise"

    max_gain: float = 64.0
    full_well_e: float = 6000.0
    read_noise_e: float = 3.0

    PARAM_BOUNDS: ClassVar = {"max_gain": (1.0, 512.0), "read_noise_e": (0.0, 50.0)}
    PARAM_LIMITS: ClassVar = {"full_well_e": (100.0, 1e6)}

    def _sigma(self) -> np.ndarray:
        return noise_sigma_lut(self.k * self.max_gain, self.full_well_e, self.read_noise_e)

    def _apply_into(self, img, depth, state, rng, out):
        add_sensor_noise(img, None, self._sigma(), rng, out)

    def _run_batch(self, imgs, depth, states, rng):
        if self.k == 0.0:
            return imgs.copy()
        return add_sensor_noise(imgs, None, self._sigma(), rng)  # one draw, shared tables
