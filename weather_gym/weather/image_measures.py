"""Image-degradation measures used to check and compare effects (no detector needed).

Example:
    >>> import numpy as np
    >>> from weather_gym.weather.image_measures import ssim
    >>> a = np.random.default_rng(0).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    >>> ssim(a, a)
    1.0
"""

from __future__ import annotations

import cv2
import numpy as np

from weather_gym.core.errors import InputError

__all__ = ["rms_contrast", "ssim"]


def _gray(img: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY).astype(np.float64)


def ssim(clean: np.ndarray, degraded: np.ndarray, sigma: float = 1.5) -> float:
    """Mean structural similarity (Wang et al. 2004) of the luma of two uint8 RGB images."""
    if clean.shape != degraded.shape:
        raise InputError(f"ssim: shapes differ: {clean.shape} vs {degraded.shape}")
    x, y = _gray(clean), _gray(degraded)
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2

    def blur(a: np.ndarray) -> np.ndarray:
        return cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)

    mx, my = blur(x), blur(y)
    vx, vy, cxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
    return round(float(s.mean()), 12)


def rms_contrast(img: np.ndarray) -> float:
    """Standard deviation of the luma, in 8-bit units."""
    return float(_gray(img).std())
