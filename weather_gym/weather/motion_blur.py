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

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.zeros((60, 80, 3), np.uint8); img[:, 40] = 255
    >>> out = make("motion_blur", k=1.0)(img, state={"speed": 0.0, "yaw_rate": 1.0, "fx": 300.0})
    >>> int((out[30] > 0).any(axis=1).sum()) > 5   # the line is smeared over ~10 px
    True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from weather_gym.weather.geometry import EgoMotion
from weather_gym.weather.registry import register_effect

__all__ = ["MotionBlur"]


@register_effect
@dataclass(frozen=True)
class MotionBlur(EgoMotion):
    """Smear from speed and yaw rate; ``k`` = fraction of the exposure time. See module doc."""

    name: ClassVar[str] = "motion_blur"

    exposure_s: float = 1 / 30

    PARAM_BOUNDS: ClassVar = {"exposure_s": (0.001, 0.1), "near_depth_m": (0.5, 20.0)}

    def _apply_into(self, img, depth, state, rng, out):
        self.smear(img, depth, state, self.k * state.get("exposure_s", self.exposure_s), out=out)
