"""Motion blur from the car's own motion during the exposure.

**Meaning of k**: the fraction of the exposure time ``exposure_s`` (``state['exposure_s']`` when
the state gives it) during which the shutter is open; the smear grows linearly with k.

Two components, each from the vehicle state (documented defaults when absent):

* **yaw** (``state['yaw_rate']``, default ``yaw_rate_rps``): the whole image slides sideways by
  ``fx * |yaw_rate| * t`` pixels, a horizontal box blur (exact for a rotation about the vertical axis).
* **forward speed** (``state['speed']``, default ``speed_mps``): the image expands about its centre
  by ``speed * t / Z`` for a point at depth ``Z``, a zoom blur. It is computed for a point at
  ``near_depth_m`` (8 taps at most, at half or quarter resolution) and blended in with weight
  ``min(near_depth_m / Z, 1)``, ``Z`` from
  the depth map, or without one from a flat ground plane (camera ``camera_height_m`` above it,
  horizon at ``horizon_frac`` of the height) — far things and the sky stay sharp.

``fx`` comes from ``state['fx']``, else from ``hfov_deg``.

``kind="linear"`` is a plain directional blur instead (a camera pan, a shaky mount, a car whose
state is unknown, e.g. a real recording): every pixel is smeared along a line of
``k * max_length_frac * W`` pixels at ``angle_deg`` (0 = horizontal), the same over the frame.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.zeros((60, 80, 3), np.uint8); img[:, 40] = 255
    >>> out = make("motion_blur", k=1.0)(img, state={"speed": 0.0, "yaw_rate": 1.0, "fx": 300.0})
    >>> int((out[30] > 0).any(axis=1).sum()) > 5   # the line is smeared over ~10 px
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather._common import into, readonly
from weather_gym.weather.geometry import EgoMotion
from weather_gym.weather.registry import register_effect

__all__ = ["MotionBlur"]


@register_effect
@dataclass(frozen=True)
class MotionBlur(EgoMotion):
    """Smear from speed and yaw rate; ``k`` = fraction of the exposure time. See module doc."""

    name: ClassVar[str] = "motion_blur"
    CHAIN_RANK: ClassVar[float] = 60
    NOMINAL_NOUN: ClassVar[str] = "motion blur"

    exposure_s: float = 1 / 30
    kind: str = "ego"
    max_length_frac: float = 0.03
    angle_deg: float = 0.0

    CHOICES: ClassVar = {"kind": ("ego", "linear")}
    PARAM_BOUNDS: ClassVar = {"exposure_s": (0.001, 0.1), "near_depth_m": (0.5, 20.0),
                              "max_length_frac": (0.003, 0.15), "angle_deg": (-90.0, 90.0)}

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        if self.kind == "linear":
            kernel = line_kernel(round(self.k * self.max_length_frac * img.shape[1], 3), float(self.angle_deg))
            into(cv2.filter2D(img, -1, kernel, dst=out, borderType=cv2.BORDER_REFLECT), out)
            return
        self.smear(img, depth, state, self.k * state.get("exposure_s", self.exposure_s), out=out)


@lru_cache(maxsize=64)
def line_kernel(length_px: float, angle_deg: float) -> np.ndarray:
    """Normalised float32 kernel of a line ``length_px`` long at ``angle_deg`` (anti-aliased: points along
    the line splatted bilinearly); a single 1 below one pixel."""
    if length_px < 1.0:
        return readonly(np.ones((1, 1), np.float32))
    half = int(math.ceil(length_px / 2.0)) + 1
    size = 2 * half + 1
    ker = np.zeros((size, size), np.float64)
    t = np.linspace(-length_px / 2.0, length_px / 2.0, int(math.ceil(4 * length_px)) + 1)
    a = math.radians(angle_deg)
    x, y = half + t * math.cos(a), half - t * math.sin(a)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(ker, (y0 + dy, x0 + dx), w)
    return readonly((ker / ker.sum()).astype(np.float32))
