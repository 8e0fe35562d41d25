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

**Binned frames**: with ``state['binning'] = n`` (the frame is the sensor image scaled down n times,
e.g. by the gap workflow), the noise is what it would be at the sensor's pixels after the scaling:
each value's expected clipped noisy level (noise at the ends of the range is clipped, which shifts
the mean: a white over-exposed sky gets darker, black shadows lighter) plus noise of the clipped
spread over n.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.full((64, 64, 3), 128, np.uint8)
    >>> out = make("noise", k=1.0)(img, rng=np.random.default_rng(0))
    >>> 5 < float(out.std()) < 30
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar, cast

import numpy as np

from weather_gym.weather._common import (
    add_sensor_noise,
    linear_of_code,
    readonly,
    sensor_noise_draw,
    srgb_slope,
)
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


def _phi(z: np.ndarray) -> np.ndarray:
    return cast(np.ndarray, np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi))


def _cdf(z: np.ndarray) -> np.ndarray:
    return cast(np.ndarray, 0.5 * (1.0 + np.vectorize(math.erf)(z / math.sqrt(2.0))))


@lru_cache(maxsize=64)
def binned_noise_luts(sigma: tuple[float, ...], binning: float) -> tuple[np.ndarray, np.ndarray]:
    """``(mean, sigma)`` float32 LUTs of sensor noise ``sigma`` (per code value) clipped to [0, 255] and
    averaged over ``binning``**2 pixels: the mean of the clipped Gaussian, and its spread over ``binning``."""
    x = np.arange(256, dtype=np.float64)
    s = np.maximum(np.asarray(sigma, np.float64), 1e-6)
    a, b = (0.0 - x) / s, (255.0 - x) / s
    pa, pb, ca, cb = _phi(a), _phi(b), _cdf(a), _cdf(b)
    inside = cb - ca
    mean = x * inside + s * (pa - pb) + 255.0 * (1.0 - cb)
    second = ((x * x + s * s) * inside + 2.0 * x * s * (pa - pb) + s * s * (a * pa - b * pb)
              + 255.0 ** 2 * (1.0 - cb))
    spread = np.sqrt(np.maximum(second - mean * mean, 0.0)) / max(float(binning), 1.0)
    return readonly(mean.astype(np.float32)), readonly(spread.astype(np.float32))


@register_effect
@dataclass(frozen=True)
class Noise(KnobEffect):
    """Sensor noise; ``k`` = gain / ``max_gain``. See module doc."""

    name: ClassVar[str] = "noise"
    CHAIN_RANK: ClassVar[float] = 100
    NOMINAL_NOUN: ClassVar[str] = "sensor noise"

    max_gain: float = 64.0
    full_well_e: float = 6000.0
    read_noise_e: float = 3.0

    PARAM_BOUNDS: ClassVar = {"max_gain": (1.0, 512.0), "read_noise_e": (0.0, 50.0)}
    PARAM_LIMITS: ClassVar = {"full_well_e": (100.0, 1e6)}

    def _sigma(self) -> np.ndarray:
        return noise_sigma_lut(self.k * self.max_gain, self.full_well_e, self.read_noise_e)

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any = None) -> Any:
        """The random words of the frame's (or batch's) noise, :func:`sensor_noise_draw`; ``None`` at k = 0."""
        return None if self.k == 0.0 else sensor_noise_draw(rng, shape)

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        n = float(state.get("binning", 1.0) or 1.0)
        if n > 1.0:
            mean, sigma = binned_noise_luts(tuple(float(v) for v in self._sigma()), n)
            add_sensor_noise(img, mean, sigma, draw, out)
            return
        add_sensor_noise(img, None, self._sigma(), draw, out)

    def _render_batch(self, imgs: np.ndarray, draws: Any, depth: np.ndarray | None,
                      states: list[dict[str, float]]) -> np.ndarray:
        if any(float(s.get("binning", 1.0) or 1.0) > 1.0 for s in states):
            out = np.empty_like(imgs)
            for i in range(imgs.shape[0]):
                self._render_into(imgs[i], draws[i:i + 1], None, states[i], out[i])
            return out
        return add_sensor_noise(imgs, None, self._sigma(), draws)  # shared tables
