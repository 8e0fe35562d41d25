"""Fading light: the study's brightness reduction, a physical low-light camera, and a night camera.

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

**Night mode** (``mode="night"``): the physical camera (same exposure, gain, motion blur and
sensor noise, same parameters) followed by what its ISP does at high gain, so that the damage keeps
growing over the whole range of k, from a light dusk to night. It works as a YUV 4:2:0 ISP does:
the luma (Rec. 601) at full resolution, the colour (each channel's offset from the luma) at half
resolution in each direction (:mod:`~weather_gym.weather._night_isp`):

* the motion smear of the longer exposure on both (one zoom blur serves the two);
* the sensor noise on the luma: 0.67 times the physical mode's sigma, what the luma of independent
  R, G and B noise has; the colour noise is what the denoiser leaves of it, the blotches below;
* a denoiser that smears fine detail (small, far cones first): a spatial smoothing of the luma of
  sigma ``denoise_px * sqrt((gain - 1) / 15)`` px, growing like the noise it must hide;
* the colour noise the denoiser leaves: low-frequency RGB blotches (zero mean over R, G, B) on a grid
  of ``chroma_cell_px`` cells, sigma ``chroma_noise * log2(gain) / 4`` code values on an 18 % grey,
  following the sensor noise of each cell's level elsewhere (stronger in shadows, weaker in highlights);
* crushed shadows: the black level set above the sensor's, ``black_level * log2(gain) / 4`` of
  full scale in linear light, taken as black (on the luma, and on each channel before its colour
  offset is taken, so crushed shadows are black in every channel);
* chroma suppression: the ISP pulls colour towards grey at high gain to hide the colour noise,
  ``desaturate * log2(gain) / 4`` of the colour offsets removed (the blotches' colour with them,
  their luma kept): colour is what tells a blue cone from a yellow one, and it fades the same way on
  every track, so the damage depends little on the scene (how many cones, how far);
* and, once the gain is at ``max_gain``, the remaining darkening of the physical mode.

The ISP is tuned per gain (ISO), as real ones are: its four stages stop growing once the gain is
at ``max_gain``. The night parameters are ignored by the other two modes.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.full((8, 8, 3), 200, np.uint8)
    >>> int(make("dim", k=0.78)(img)[0, 0, 0])    # trunc(0.22 * 200)
    44
    >>> out = make("dim", k=0.5, mode="physical")(img, rng=np.random.default_rng(0))
    >>> 150 < float(out.mean()) < 250              # auto-exposure brings the level back
    True
    >>> night = make("dim", k=1.0, mode="night")(img, rng=np.random.default_rng(0))
    >>> float(night.mean()) < 40                    # out of exposure and gain: dark
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather._common import (
    add_sensor_noise,
    flat,
    gauss_lut,
    into,
    linear_of_code,
    readonly,
    sensor_noise_draw,
    smooth,
    srgb_encode,
    srgb_slope,
)
from weather_gym.weather.geometry import EgoMotion
from weather_gym.weather.registry import register_effect

__all__ = ["Dim", "add_chroma_blotches", "auto_exposure", "black_level_lut", "brightness_lut", "chroma_draw",
           "chroma_grid", "chroma_offsets"]


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


@lru_cache(maxsize=256)
def black_level_lut(black: float) -> np.ndarray:
    """Code value -> code value with the linear level ``black`` taken as black (crushed shadows).

    ``x -> (x - black) / (1 - black)`` in linear light, clipped at 0: what an ISP's black-level
    subtraction does when it sets black above the sensor's (to hide the noise floor at high gain).
    """
    x = linear_of_code()
    y = np.maximum(x - black, 0.0) / (1.0 - black)
    return readonly(np.clip(np.rint(255.0 * srgb_encode(y)), 0, 255).astype(np.uint8))


def chroma_grid(shape: tuple[int, ...], cell_px: float) -> tuple[int, int]:
    """``(rows, cols)`` of the grid of ``cell_px`` cells the colour noise is drawn on."""
    return max(int(math.ceil(shape[0] / cell_px)), 1), max(int(math.ceil(shape[1] / cell_px)), 1)


def chroma_draw(rng: np.random.Generator, shape: tuple[int, ...], cell_px: float) -> np.ndarray:
    """The random bytes of :func:`add_chroma_blotches` on a frame of ``shape``: 3 per grid cell."""
    gh, gw = chroma_grid(shape, cell_px)
    n = gh * gw * 3
    return rng.bit_generator.random_raw(-(-n // 8)).view(np.uint8)[:n]


def chroma_offsets(raw: np.ndarray, grid: tuple[int, int], sigma: float,
                   weight: np.ndarray | None = None) -> np.ndarray:
    """The colour blotches on their grid: float32 ``rows x cols x 3`` zero-luma RGB offsets of std
    ``sigma`` (code values), times ``weight`` per cell when given, from the random bytes ``raw``
    (:func:`chroma_draw`)."""
    gh, gw = grid
    # standard normals as random bytes through 256 equiprobable quantiles
    z: np.ndarray = gauss_lut()[raw].reshape(gh, gw, 3)
    mean = z[:, :, 0] + z[:, :, 1]  # colour only: the three offsets sum to zero (the float32 mean over the
    mean += z[:, :, 2]              # three, as numpy's z.mean(axis=2) sums and divides, in a third of its time)
    mean /= 3
    z -= mean[:, :, None]
    z *= np.float32(sigma * math.sqrt(1.5))
    if weight is not None:
        z *= weight[:, :, None]
    return z


def add_chroma_blotches(img: np.ndarray, sigma: float, cell_px: float, raw: np.ndarray | np.random.Generator,
                        weight: np.ndarray | None = None) -> None:
    """Add low-frequency colour noise in place: zero-luma RGB offsets of std ``sigma`` (code values)
    drawn on a grid of ``cell_px`` cells and enlarged smoothly (what a denoiser leaves of colour noise).

    ``raw``: the random bytes, :func:`chroma_draw` (or a generator to draw them from);
    ``weight``: optional float32 ``(rows, cols)`` factor per cell (:func:`chroma_grid`). (The night
    camera adds its blotches to its half-resolution colour instead: :mod:`~weather_gym.weather._night_isp`.)
    """
    if isinstance(raw, np.random.Generator):
        raw = chroma_draw(raw, img.shape, cell_px)
    h, w = img.shape[:2]
    z = chroma_offsets(raw, chroma_grid(img.shape, cell_px), sigma, weight)
    z += 128.0
    grid = np.clip(np.rint(z, out=z), 0, 255, out=z).astype(np.uint8)
    big = cv2.resize(grid, (w, h), interpolation=cv2.INTER_LINEAR)
    f, b = flat(img), flat(big)
    # + the positive part of big - 128 then - its negative part, each saturating, is img + big - 128
    # saturated once (the first never goes below 0, the second never above 255): one exact pass
    into(cv2.addWeighted(f, 1.0, b, 1.0, -128.0, dst=f), f)


#: Code value at which ``chroma_noise`` is the colour noise's sigma (18 % grey).
_CHROMA_REF_CODE = 118
#: The luma's share of independent noise of the same sigma in R, G and B (Rec. 601 weights):
#: ``sqrt(0.299^2 + 0.587^2 + 0.114^2)``.
_LUMA_NOISE = math.sqrt(0.299 ** 2 + 0.587 ** 2 + 0.114 ** 2)


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


@lru_cache(maxsize=64)
def _night_luts(residual: float, gain: float, full_well_e: float, read_noise_e: float,
                black: float) -> tuple[np.ndarray, ...]:
    """``(tone, luma noise sigma, colour tone, black-level table, sensor noise sigma)`` of the night camera.

    ``tone`` and ``sigma`` are :func:`_physical_luts` (the luma's sigma scaled by :data:`_LUMA_NOISE`);
    the colour's tone is the tone followed by the black level (float32), so the colour of crushed
    shadows goes with them.
    """
    tone, sigma = _physical_luts(residual, gain, full_well_e, read_noise_e)
    crush = black_level_lut(black) if black > 0 else readonly(np.arange(256, dtype=np.uint8))
    colour = crush[np.clip(np.rint(tone), 0, 255).astype(np.uint8)].astype(np.float32)
    return tone, readonly(sigma * np.float32(_LUMA_NOISE)), readonly(colour), crush, sigma


@register_effect
@dataclass(frozen=True)
class Dim(EgoMotion):
    """Fading light; ``k`` = 1 - brightness factor (faithful) or light lost in ``stops`` (physical)."""

    name: ClassVar[str] = "dim"
    CONDITION: ClassVar[str] = "low_light"
    CHAIN_RANK: ClassVar[float] = 80
    NOMINAL_K: ClassVar[tuple[float, ...] | None] = None  # its presets rows are calibrated

    mode: str = "faithful"
    stops: float = 12.0
    exposure_s: float = 0.002
    max_exposure_s: float = 1 / 60
    max_gain: float = 16.0
    full_well_e: float = 6000.0
    read_noise_e: float = 3.0
    denoise_px: float = 0.5
    chroma_noise: float = 16.0
    chroma_cell_px: float = 8.0
    black_level: float = 0.004
    desaturate: float = 0.8

    CHOICES: ClassVar = {"mode": ("faithful", "physical", "night")}
    PARAM_BOUNDS: ClassVar = {
        "stops": (2.0, 20.0),
        "max_exposure_s": (0.001, 0.1),
        "max_gain": (1.0, 256.0),
        "read_noise_e": (0.0, 50.0),
        "denoise_px": (0.0, 3.0),
        "chroma_noise": (0.0, 40.0),
        "black_level": (0.0, 0.1),
        "desaturate": (0.0, 1.0),
    }
    PARAM_LIMITS: ClassVar = {**EgoMotion.PARAM_LIMITS, "exposure_s": (1e-5, 0.1), "full_well_e": (100.0, 1e6),
                              "chroma_cell_px": (2.0, 64.0)}

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

    def _physical(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                  out: np.ndarray) -> np.ndarray:
        t, gain, residual = self.exposure()
        smeared = self.smear(img, depth, state, t - self.exposure_s)  # img itself when there is no blur
        mean, sigma = _physical_luts(residual, gain, self.full_well_e, self.read_noise_e)
        add_sensor_noise(smeared, mean, sigma, draw[0], out)
        return smeared

    # -- night ---------------------------------------------------------------------------------
    def isp(self) -> tuple[float, float, float, float]:
        """``(denoiser sigma px, chroma blotch sigma in code values, black level, desaturation)`` at this k.

        A camera's ISP is tuned per sensor gain (ISO), so all four follow the gain the
        auto-exposure uses: the denoiser's blur grows like the noise it must hide,
        ``sqrt((gain - 1) / 15)``; the colour noise, the black level and the chroma suppression grow
        with the stops of gain, ``log2(gain) / 4``. The parameters are their values at gain 16. Once
        the gain is at its maximum they stay, and only the darkening goes on (night mode).
        """
        _, gain, _ = self.exposure()
        gain = 1.0 if gain < 1.0 + 1e-6 else gain  # rounding of the auto-exposure's arithmetic
        stops = math.log2(gain) / 4.0
        return (self.denoise_px * math.sqrt((gain - 1.0) / 15.0), self.chroma_noise * stops,
                min(self.black_level * stops, 0.5), min(self.desaturate * stops, 1.0))

    def _night(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
               out: np.ndarray) -> None:
        from weather_gym.weather._area import area_shrink  # numba loads here
        from weather_gym.weather._night_isp import blotch_grid, chroma_plane, combine

        t, gain, residual = self.exposure()
        sigma, chroma, black, desat = self.isp()
        tone, luma_noise, colour_tone, crush, noise = _night_luts(residual, gain, self.full_well_e, self.read_noise_e,
                                                                  black)
        h, w = img.shape[:2]
        # luma (Rec. 601) at full resolution, colour at half: the motion smear of the longer exposure
        luma, half = self.smear_split(img, depth, state, t - self.exposure_s)
        # sensor noise on the luma, then the ISP's denoiser (a spatial smoothing that grows with the gain)
        noisy = np.empty((h, w), np.uint8)
        add_sensor_noise(luma.reshape(h, w, 1), tone, luma_noise, draw[0], noisy.reshape(h, w, 1))
        if sigma >= 0.3:
            smooth(noisy, sigma, noisy, exact=True)
        blotches = None
        if chroma > 0:  # colour noise follows the sensor noise of each cell's level
            gh, gw = chroma_grid(img.shape, self.chroma_cell_px)
            level = cv2.cvtColor(area_shrink(half, (gw, gh)), cv2.COLOR_RGB2GRAY)
            grid = blotch_grid(draw[1], gauss_lut(), level, noise, float(noise[_CHROMA_REF_CODE]), chroma)
            blotches = cv2.resize(grid, (half.shape[1], half.shape[0]), interpolation=cv2.INTER_LINEAR)
        # colour offsets through the tone curve and the black level, suppressed; the luma's black level
        combine(noisy, crush, chroma_plane(half, colour_tone, blotches, 1.0 - desat), out)

    # -- sampling and rendering ------------------------------------------------------------------
    def _sample_frame(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any) -> Any:
        """``(sensor noise words, chroma bytes or None)``; nothing in the faithful mode. The night
        camera's sensor noise is drawn for its luma only (one value per pixel)."""
        if self.mode == "faithful":
            return None
        if self.mode == "night":
            shape = (*shape[:-1], 1)
        noise = sensor_noise_draw(rng, shape)
        if self.mode == "night" and self.isp()[1] > 0:
            return noise, chroma_draw(rng, shape, self.chroma_cell_px)
        return noise, None

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        if self.mode == "faithful":
            self._faithful(img, out)
        elif self.mode == "physical":
            self._physical(img, draw, depth, state, out)
        else:
            self._night(img, draw, depth, state, out)

    def _render_batch(self, imgs: np.ndarray, draws: list[Any] | None, depth: np.ndarray | None,
                      states: list[dict[str, float]]) -> np.ndarray:
        if self.mode == "faithful":
            return self._faithful(imgs, np.empty_like(imgs))
        return super()._render_batch(imgs, draws, depth, states)
