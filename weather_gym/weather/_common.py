"""Small helpers shared by the effects: sRGB transfer curve, fast Gaussian noise, camera geometry.

Everything returned from a cache is read-only.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather._common import srgb_decode, srgb_encode
    >>> bool(np.allclose(srgb_encode(srgb_decode(np.arange(256) / 255)), np.arange(256) / 255))
    True
"""

from __future__ import annotations

import math
from functools import lru_cache
from statistics import NormalDist

import cv2
import numpy as np

#: Horizontal field of view assumed when neither the state nor the effect gives a focal length.
DEFAULT_HFOV_DEG = 90.0


def readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def flat(img: np.ndarray) -> np.ndarray:
    """View a C-contiguous ``(..., W, 3)`` uint8 image as 2-D ``(rows, W*3)`` (fast single-channel cv2)."""
    return img.reshape(-1, img.shape[-2] * img.shape[-1])


def srgb_decode(v: np.ndarray) -> np.ndarray:
    """sRGB encoded value in [0, 1] -> linear light in [0, 1] (IEC 61966-2-1)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] -> sRGB encoded value in [0, 1] (clipped)."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_slope(x: np.ndarray) -> np.ndarray:
    """d(encoded)/d(linear) at linear value ``x``."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92, 1.055 / 2.4 * np.power(np.maximum(x, 1e-12), 1 / 2.4 - 1))


@lru_cache(maxsize=1)
def linear_of_code() -> np.ndarray:
    """Linear light of each 8-bit code value (256,)."""
    return readonly(srgb_decode(np.arange(256) / 255.0))


@lru_cache(maxsize=1)
def gauss_lut() -> np.ndarray:
    """256 equiprobable standard-normal quantiles (unit variance), float32.

    Mapping a uniform random byte through this table gives a standard normal quantised to 256
    levels (truncated at +-2.9 sigma), over 10x cheaper than ``Generator.standard_normal``.
    """
    q = np.array([NormalDist().inv_cdf((i + 0.5) / 256.0) for i in range(256)])
    q /= q.std()
    return readonly(q.astype(np.float32))


def random_bytes(rng: np.random.Generator, shape: tuple[int, ...], frames: int = 1) -> np.ndarray:
    """Uniform random uint8 array drawn from ``rng`` (64 random bits give 8 bytes).

    Drawn frame by frame (``frames`` equal chunks), so a batch gets the same bytes as a loop.
    """
    n = int(np.prod(shape))
    per = n // frames
    chunks = [rng.bit_generator.random_raw((per + 7) // 8).view(np.uint8)[:per] for _ in range(frames)]
    return (chunks[0] if frames == 1 else np.concatenate(chunks)).reshape(shape)


@lru_cache(maxsize=1)
def _gauss_lut16() -> np.ndarray:
    """:func:`gauss_lut` in fixed point (1/16 of a standard deviation), int16."""
    return readonly(np.rint(gauss_lut() * 16).astype(np.int16))


def add_sensor_noise(img: np.ndarray, mean_lut: np.ndarray | None, sigma_lut: np.ndarray,
                     rng: np.random.Generator) -> np.ndarray:
    """``round(mean_lut[I] + sigma_lut[I] * z)`` with ``z`` standard normal per pixel and channel.

    ``mean_lut`` None means the identity. ``img`` is a C-contiguous uint8 ``H x W x 3`` frame or an
    ``N x H x W x 3`` batch (the same noise as frame-by-frame calls). Computed in 16-bit fixed
    point (sigma in 1/8 code values, z in 1/16 steps), mean and noise each rounded to whole code
    values, clipped to 0-255.
    """
    f = flat(img)
    frames = img.shape[0] if img.ndim == 4 else 1
    z = cv2.LUT(random_bytes(rng, f.shape, frames), _gauss_lut16())
    s = cv2.LUT(f, np.rint(np.minimum(sigma_lut, 4000.0) * 8).astype(np.int16))
    noise = cv2.multiply(s, z, scale=1 / 128)  # whole code values
    base = f if mean_lut is None else cv2.LUT(f, np.clip(np.rint(mean_lut), 0, 255).astype(np.uint8))
    return cv2.add(base, noise, dtype=cv2.CV_8U).reshape(img.shape)


def focal_px(state: dict[str, float], width: int, hfov_deg: float) -> float:
    """Focal length in pixels: ``state['fx']`` when given, else from the horizontal field of view."""
    if "fx" in state:
        return state["fx"]
    return 0.5 * width / math.tan(math.radians(hfov_deg) / 2)


@lru_cache(maxsize=16)
def ray_factor(h: int, w: int, fx: float) -> np.ndarray:
    """Range / z-depth of each pixel for a pinhole camera with square pixels, principal point at centre."""
    u = (np.arange(w, dtype=np.float32) - (w - 1) / 2) / fx
    v = (np.arange(h, dtype=np.float32) - (h - 1) / 2) / fx
    return readonly(np.sqrt(1.0 + u[None, :] ** 2 + v[:, None] ** 2).astype(np.float32))


@lru_cache(maxsize=16)
def ground_depth(h: int, w: int, fx: float, camera_height_m: float, horizon_frac: float,
                 far_m: float) -> np.ndarray:
    """Fallback z-depth when none is given: a flat ground plane seen by a level camera.

    A row ``v`` pixels below the horizon row (``horizon_frac * H``) sees the ground at
    ``z = fx * camera_height / v``; rows at or above the horizon (sky, far background) get ``far_m``.
    """
    v = np.arange(h, dtype=np.float64) + 0.5 - horizon_frac * h
    z = np.full(h, far_m)
    below = v > 0
    z[below] = np.minimum(fx * camera_height_m / v[below], far_m)
    return readonly(np.repeat(z.astype(np.float32)[:, None], w, axis=1))


def scene_depth(depth: np.ndarray | None, h: int, w: int, fx: float, camera_height_m: float,
                horizon_frac: float, far_m: float, who: str) -> np.ndarray:
    """The given depth map (validated finite, >= 0) or the flat-ground fallback."""
    if depth is None:
        return ground_depth(h, w, fx, camera_height_m, horizon_frac, far_m)
    if not np.isfinite(depth).all() or float(depth.min()) < 0:
        raise ValueError(f"{who}: depth must be finite metres >= 0 (got NaN, inf or negative values)")
    return depth


def lerp_u8(img: np.ndarray, other: np.ndarray, w3: np.ndarray) -> np.ndarray:
    """``img + (other - img) * w3 / 255`` for uint8 images and a uint8 3-channel weight map."""
    a = cv2.multiply(img, cv2.bitwise_not(w3), scale=1 / 255)
    b = cv2.multiply(other, w3, scale=1 / 255)
    return cv2.add(a, b)


def lerp_to_gray(img: np.ndarray, gray: float, w3: np.ndarray) -> np.ndarray:
    """``img + (gray - img) * w3 / 255``: blend towards a constant gray level ``gray`` (0-255)."""
    a = cv2.multiply(img, cv2.bitwise_not(w3), scale=1 / 255)
    return cv2.add(a, cv2.convertScaleAbs(w3, alpha=gray / 255.0))


def weight3(w: np.ndarray) -> np.ndarray:
    """Float weights in [0, 1] (H x W) -> uint8 3-channel weights (255 = 1)."""
    return cv2.cvtColor(cv2.convertScaleAbs(w, alpha=255.0), cv2.COLOR_GRAY2RGB)


def smooth(img: np.ndarray, sigma: float) -> np.ndarray:
    """Fast Gaussian-like blur of standard deviation ``sigma`` px (three box passes, new array).

    Small blurs use an exact Gaussian; larger ones three passes of an odd box of width ``n``
    (variance ``(n^2 - 1) / 4``); very large ones run on a half-resolution copy.
    """
    if sigma < 0.3:
        return img.copy()
    h, w = img.shape[:2]
    if sigma < 1.5:
        ksize = 2 * math.ceil(2.5 * sigma) + 1
        return cv2.GaussianBlur(img, (ksize, ksize), sigma, borderType=cv2.BORDER_REFLECT)
    if sigma > 6 and min(h, w) >= 8:
        small = cv2.resize(img, (max(w // 2, 1), max(h // 2, 1)), interpolation=cv2.INTER_AREA)
        return cv2.resize(smooth(small, sigma / 2), (w, h), interpolation=cv2.INTER_LINEAR)
    n = 2 * int(round((math.sqrt(4 * sigma * sigma + 1) - 1) / 2)) + 1
    out = cv2.blur(img, (n, n), borderType=cv2.BORDER_REFLECT)
    out = cv2.blur(out, (n, n), borderType=cv2.BORDER_REFLECT)
    return cv2.blur(out, (n, n), borderType=cv2.BORDER_REFLECT)
