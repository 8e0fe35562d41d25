"""Fog and haze by Koschmieder's law: contrast fades with distance towards a bright airlight.

``I = J * t + A * (1 - t)`` with transmittance ``t = exp(-beta * range)``, ``range`` the distance
along each pixel's ray (z-depth times the ray's obliquity) and ``A = airlight * 255``; ``airlight_tint``
colours it as a sky does: at ``t > 0`` the red channel of ``A`` is ``(1 - t)`` of the blue (a bluish
haze), at ``t < 0`` the blue is ``(1 + t)`` of the red (a warm one), green half-way; 0 (the default) is grey.
``airlight_green`` is the other axis of a white balance (its "tint"): at ``g > 0`` red and blue are
``(1 - g)`` of what they were (a greenish airlight), at ``g < 0`` green is ``(1 + g)`` of it (magenta).

**Where it mixes** (``space``): ``"srgb"`` (the default, what the presets are calibrated with) mixes the
8-bit code values; ``"linear"`` mixes scene radiance, as the law is stated: the image and the airlight
are decoded to linear light (sRGB curve, a 256-entry table), mixed, and encoded back (a 65536-entry
table), within one code value of the exact curve. Both tend to the same airlight code far away.

**Meaning of k**: the extinction coefficient as a fraction of the densest fog:
``beta = k * 3.912 / min_visibility_m`` (meteorological visibility ``3.912 / beta``), so k = 1 is
fog with ``min_visibility_m`` (15 m) visibility and k = 0.1 is 150 m.

**Depth**: with a depth map (metres, z-depth) the fog is exact per pixel. Without one — the
documented fallback — the scene is taken as a flat ground plane seen by a level camera
``camera_height_m`` above it, horizon at ``horizon_frac`` of the image height and ``far_m`` above
the horizon: right for the track surface and the cones' bases, approximate for the rest.
``fx`` comes from ``state['fx']``, else from ``hfov_deg``.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.zeros((20, 30, 3), np.uint8)
    >>> depth = np.full((20, 30), 15.0, np.float32)
    >>> out = make("fog", k=1.0)(img, depth=depth)     # one visibility away: 1 - e^-3.912 = 98 %
    >>> 200 <= int(out[10, 15, 0]) <= 217
    True
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather._common import (
    blend_into,
    blend_terms,
    focal_px,
    ground_depth,
    linear_of_code,
    ray_factor,
    readonly,
    scene_depth,
    srgb_encode,
)
from weather_gym.weather.geometry import CameraGeometry
from weather_gym.weather.registry import register_effect

__all__ = ["Fog", "KOSCHMIEDER"]

#: ``-ln(0.02)``: visibility = KOSCHMIEDER / extinction coefficient (2 % contrast threshold).
KOSCHMIEDER = 3.912


def _transmittance(z: np.ndarray, ray: np.ndarray, beta: float) -> np.ndarray:
    """float32 ``exp(-beta * z * ray)``, single channel."""
    return cv2.exp(cv2.multiply(z, ray, scale=-beta))


@lru_cache(maxsize=1)
def _linear_u16() -> np.ndarray:
    """Linear light of each 8-bit code value, scaled to 0-65535 (uint16, 256 entries)."""
    return readonly(np.rint(linear_of_code() * 65535.0).astype(np.uint16))


@lru_cache(maxsize=1)
def _code_of_u16() -> np.ndarray:
    """The 8-bit sRGB code of each 16-bit linear level (uint8, 65536 entries)."""
    return readonly(np.rint(255.0 * srgb_encode(np.arange(65536) / 65535.0)).astype(np.uint8))


_SCRATCH = threading.local()  # per-thread work arrays of the linear blend: fresh 1.5 MB arrays per frame cost page faults


def _scratch(name: str, shape: tuple[int, ...]) -> np.ndarray:
    """This thread's uint16 work array ``name`` of ``shape`` (reused from frame to frame)."""
    buf = getattr(_SCRATCH, name, None)
    if buf is None or buf.shape != shape:
        buf = np.empty(shape, np.uint16)
        setattr(_SCRATCH, name, buf)
    return buf


def _linear_terms(t: np.ndarray, gray: float | tuple[float, float, float],
                  scratch: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """uint16 RGB ``65535 t`` and ``65535 A_lin (1 - t)`` from the float32 transmittance ``t``
    (in this thread's work arrays with ``scratch``: valid until its next call)."""
    codes = gray if isinstance(gray, tuple) else (gray, gray, gray)
    a_lin = [float(v) for v in np.interp(codes, np.arange(256), _linear_u16())]  # airlight code -> linear
    shape = (*t.shape, 3)
    t3 = _scratch("t3", shape) if scratch else np.empty(shape, np.uint16)
    add3 = _scratch("add3", shape) if scratch else np.empty(shape, np.uint16)
    t16 = _scratch("t16", t.shape) if scratch else np.empty(t.shape, np.uint16)
    np.copyto(t16, cv2.add(cv2.multiply(t, 65535.0), 0.5), casting="unsafe")  # rounded
    cv2.cvtColor(t16, cv2.COLOR_GRAY2RGB, dst=t3)
    inv = cv2.bitwise_not(t16)  # 65535 (1 - t)
    if a_lin[0] == a_lin[1] == a_lin[2]:
        cv2.cvtColor(cv2.multiply(inv, a_lin[0], scale=1 / 65535), cv2.COLOR_GRAY2RGB, dst=add3)
    else:  # per plane: OpenCV's multiply by a 3-channel scalar is several times slower
        cv2.merge([cv2.multiply(inv, a, scale=1 / 65535) for a in a_lin], dst=add3)
    return t3, add3


def _blend_linear(img: np.ndarray, terms: tuple[np.ndarray, np.ndarray], out: np.ndarray) -> np.ndarray:
    """``out = enc(dec(img) * t + A_lin * (1 - t))`` with the tables of :func:`_linear_u16` / :func:`_code_of_u16`."""
    t3, add3 = terms
    x: np.ndarray = _scratch("x", img.shape)
    cv2.LUT(img, _linear_u16(), dst=x)
    cv2.multiply(x, t3, dst=x, scale=1 / 65535)
    cv2.add(x, add3, dst=x)
    np.take(_code_of_u16(), x, out=out, mode="clip")  # "clip": unbuffered (all indices are valid)
    return out


def _terms(space: str, z: np.ndarray, ray: np.ndarray, beta: float, gray: float | tuple[float, float, float],
           scratch: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The blend terms of fog ``beta`` over depth ``z`` in ``space``: ``blend_terms`` of the uint8 weight
    ``255 (1 - t)`` (``"srgb"``) or :func:`_linear_terms` of ``t`` (``"linear"``; ``scratch`` as there)."""
    t = _transmittance(z, ray, beta)
    if space == "linear":
        return _linear_terms(t, gray, scratch=scratch)
    return blend_terms(cv2.convertScaleAbs(t, alpha=-255.0, beta=255.0), gray)


@lru_cache(maxsize=32)
def _fallback_terms(space: str, h: int, w: int, fx: float, beta: float, camera_height_m: float,
                    horizon_frac: float, far_m: float,
                    gray: float | tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_terms` over the flat ground's depth (no depth map), read-only: cached per size and k."""
    z = ground_depth(h, w, fx, camera_height_m, horizon_frac, far_m)
    a, b = _terms(space, z, ray_factor(h, w, fx), beta, gray)
    return readonly(a), readonly(b)


@register_effect
@dataclass(frozen=True)
class Fog(CameraGeometry):
    """Koschmieder haze; ``k`` = extinction / that of ``min_visibility_m`` fog. See module doc."""

    name: ClassVar[str] = "fog"
    CHAIN_RANK: ClassVar[float] = 10
    NOMINAL_NOUN: ClassVar[str] = "fog"

    min_visibility_m: float = 15.0
    airlight: float = 0.85
    airlight_tint: float = 0.0
    airlight_green: float = 0.0
    space: str = "srgb"

    PARAM_BOUNDS: ClassVar = {"min_visibility_m": (2.0, 500.0), "airlight": (0.3, 1.0),
                              "airlight_tint": (-0.2, 0.2), "airlight_green": (-0.2, 0.2)}
    CHOICES: ClassVar = {"space": ("srgb", "linear")}

    @property
    def beta(self) -> float:
        """Extinction coefficient (1/m) at this k."""
        return self.k * KOSCHMIEDER / self.min_visibility_m

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        h, w = img.shape[:2]
        fx = focal_px(state, w, self.hfov_deg)
        a = 255.0 * self.airlight
        gray: float | tuple[float, float, float] = a
        if self.airlight_tint:  # the brightest channel keeps the airlight level (RGB order)
            t = self.airlight_tint
            gray = (a * (1.0 - max(t, 0.0)), a * (1.0 - abs(t) / 2.0), a * (1.0 + min(t, 0.0)))
        if self.airlight_green:
            g = self.airlight_green
            r0, g0, b0 = gray if isinstance(gray, tuple) else (a, a, a)
            gray = (r0 * (1.0 - max(g, 0.0)), g0 * (1.0 + min(g, 0.0)), b0 * (1.0 - max(g, 0.0)))
        if depth is None:  # cached per size and k
            terms = _fallback_terms(self.space, h, w, fx, self.beta, self.camera_height_m, self.horizon_frac,
                                    self.far_m, gray)
        else:
            z = scene_depth(depth, h, w, fx, self.camera_height_m, self.horizon_frac, self.far_m, self.name)
            terms = _terms(self.space, z, ray_factor(h, w, fx), self.beta, gray, scratch=True)
        if self.space == "linear":
            _blend_linear(img, terms, out)
        else:
            blend_into(img, terms, out)
