"""Fading light: the study's brightness reduction, and a physical low-light camera model.

**Faithful mode** (``mode="faithful"``, default): exactly the study's ``PIL.ImageEnhance.Brightness``
with factor ``1 - k``: every 8-bit value ``I`` becomes ``trunc(float32(1 - k) * I)``, byte for byte
as Pillow computes it (checked against Pillow in the tests), in one OpenCV pass.

**Physical mode** (``mode="physical"``): what a real camera does as the light fades, which the study
left out (its discussion names blur and the camera raising its ISO gain):

* k is logarithmic here: the scene gets ``2 ** (-k * stops)`` of the light of the clean frame
  (``stops = 12``: k = 1 is 1/4096, roughly overcast day to late dusk).
* auto-exposure restores the brightness, first with a longer exposure (from ``exposure_s`` up to
  ``max_exposure_s``), then with gain (up to ``max_gain``); only the light it cannot make up for
  darkens the image.
* the longer exposure smears the image by the car's motion (:mod:`~weather_gym.weather.motion_blur`,
  from the state's speed and yaw rate or ``speed_mps`` / ``yaw_rate_rps``);
* fewer photons times more gain means more noise: Poisson shot noise and Gaussian read noise
  (``full_well_e``, ``read_noise_e``), on top of the noise the clean frame already had.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.full((8, 8, 3), 200, np.uint8)
    >>> int(make("dim", k=0.78)(img)[0, 0, 0])    # trunc(0.22 * 200)
    44
    >>> out = make("dim", k=0.5, mode="physical")(img, rng=np.random.default_rng(0))
    >>> 150 < float(out.mean()) < 250              # auto-exposure brings the level back
    True
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import ClassVar

import cv2
import numpy as np

from weather_gym.weather._common import (
    add_sensor_noise,
    flat,
    into,
    linear_of_code,
    readonly,
    srgb_encode,
    srgb_slope,
)
from weather_gym.weather.geometry import EgoMotion
from weather_gym.weather.registry import register_effect

__all__ = ["Dim", "auto_exposure", "brightness_lut"]


@lru_cache(maxsize=256)
def brightness_lut(factor: float) -> np.ndarray:
    """Pillow's ``Image.blend(black, img, factor)`` for uint8: ``trunc(float32(factor) * I)``."""
    v = np.float32(factor) * np.arange(256, dtype=np.float32)
    return readonly(np.clip(v, 0, 255).astype(np.uint8))


@lru_cache(maxsize=256)
def _scale_plan(factor: float) -> tuple[float, float] | None:
    """``(alpha, beta)`` with ``convertScaleAbs(I, alpha, beta) == brightness_lut(factor)[I]`` for all I.

    ``round(I * alpha + beta)`` equals the truncation when ``beta = -0.5 + delta`` keeps every
    fractional part clear of the rounding edges by a margin; ``None`` when no such ``delta`` exists
    (then a look-up table is used).
    """
    p = np.float32(factor) * np.arange(256, dtype=np.float32)
    frac = (p - np.floor(p)).astype(np.float64)
    room = 1.0 - float(frac.max())
    if room < 4e-4 or float(p.max()) >= 255.5:
        return None
    return float(factor), -0.5 + room / 2


def auto_exposure(light: float, exposure_s: float, max_exposure_s: float,
                  max_gain: float) -> tuple[float, float, float]:
    """``(exposure time, gain, residual brightness)`` an auto-exposure picks for ``light`` (<= 1)."""
    need = 1.0 / max(light, 1e-12)
    t = max(min(exposure_s * need, max_exposure_s), exposure_s)
    gain = min(max(need * exposure_s / t, 1.0), max_gain)
    residual = min(light * (t / exposure_s) * gain, 1.0)
    return t, gain, residual


@lru_cache(maxsize=64)
def _physical_luts(residual: float, gain: float, full_well_e: float,
                   read_noise_e: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean and extra-noise sigma LUTs (code values) of the dimmed, amplified sensor."""
    x = linear_of_code()
    y = residual * x
    var_now = gain * y / full_well_e + (gain * read_noise_e / full_well_e) ** 2
    var_clean = residual ** 2 * (x / full_well_e + (read_noise_e / full_well_e) ** 2)
    sigma = 255.0 * srgb_slope(y) * np.sqrt(np.maximum(var_now - var_clean, 0.0))
    mean = 255.0 * srgb_encode(y)
    return readonly(mean.astype(np.float32)), readonly(sigma.astype(np.float32))


@register_effect
@dataclass(frozen=True)
class Dim(EgoMotion):
    """Fading light; ``k`` = 1 - brightness factor (faithful) or light lost in ``stops`` (physical)."""

    name: ClassVar[str] = "dim"

    mode: str = "faithful"
    stops: float = 12.0
    exposure_s: float = 0.002
    max_exposure_s: float = 1 / 60
    max_gain: float = 16.0
    full_well_e: float = 6000.0
    read_noise_e: float = 3.0

    CHOICES: ClassVar = {"mode": ("faithful", "physical")}
    PARAM_BOUNDS: ClassVar = {
        "stops": (2.0, 20.0),
        "max_exposure_s": (0.001, 0.1),
        "max_gain": (1.0, 256.0),
        "read_noise_e": (0.0, 50.0),
    }
    PARAM_LIMITS: ClassVar = {**EgoMotion.PARAM_LIMITS, "exposure_s": (1e-5, 0.1), "full_well_e": (100.0, 1e6)}

    # -- faithful ------------------------------------------------------------------------------
    def _faithful(self, img: np.ndarray, out: np.ndarray) -> np.ndarray:
        factor = 1.0 - self.k
        plan = _scale_plan(factor)
        f, o = flat(img), flat(out)
        if plan is None:
            into(cv2.LUT(f, brightness_lut(factor), dst=o), o)
        else:
            into(cv2.convertScaleAbs(f, dst=o, alpha=plan[0], beta=plan[1]), o)
        return out

    # -- physical ------------------------------------------------------------------------------
    def exposure(self) -> tuple[float, float, float]:
        """``(exposure time s, gain, residual brightness)`` chosen by the auto-exposure at this k."""
        return auto_exposure(2.0 ** (-self.k * self.stops), self.exposure_s, self.max_exposure_s,
                             self.max_gain)

    def _physical(self, img, depth, state, rng, out) -> None:
        t, gain, residual = self.exposure()
        smeared = self.smear(img, depth, state, t - self.exposure_s)  # img itself when there is no blur
        mean, sigma = _physical_luts(residual, gain, self.full_well_e, self.read_noise_e)
        add_sensor_noise(smeared, mean, sigma, rng, out)

    def _apply_into(self, img, depth, state, rng, out):
        if self.mode == "faithful":
            self._faithful(img, out)
        else:
            self._physical(img, depth, state, rng, out)

    def _run_batch(self, imgs, depth, states, rng):
        if self.mode == "faithful":
            return imgs.copy() if self.k == 0.0 else self._faithful(imgs, np.empty_like(imgs))
        return super()._run_batch(imgs, depth, states, rng)
