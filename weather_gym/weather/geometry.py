"""Camera geometry and the car's own motion, shared by the effects that need them.

``CameraGeometry``: the pinhole camera and flat-ground fallback of effects that need depth when
none is given (fog, motion blur, physical dim). ``EgoMotion`` adds the vehicle motion defaults and
:meth:`EgoMotion.smear`, the motion blur of an exposure (see :mod:`weather_gym.weather.motion_blur`).

Example:
    >>> from weather_gym.weather import make
    >>> make("fog", k=0.5).camera_height_m
    1.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import cv2
import numpy as np

from weather_gym.core.errors import LimitError
from weather_gym.weather._common import (
    DEFAULT_HFOV_DEG,
    depth_min,
    focal_px,
    into,
    readonly,
    scene_depth,
)
from weather_gym.weather.base import KnobEffect

__all__ = ["CameraGeometry", "EgoMotion", "motion_smear", "smear_split"]


def _zoom(img: np.ndarray, c: float) -> np.ndarray:
    """Magnify ``img`` by ``c >= 1`` about its centre, same size."""
    h, w = img.shape[:2]
    bw, bh = max(int(round(w * c)), w), max(int(round(h * c)), h)
    if (bw, bh) == (w, h):
        return img
    big = cv2.resize(img, (bw, bh), interpolation=cv2.INTER_LINEAR)
    x0, y0 = (bw - w) // 2, (bh - h) // 2
    return big[y0:y0 + h, x0:x0 + w]


def _shrink(img: np.ndarray, f: int) -> np.ndarray:
    """``img`` reduced ``f`` times (2 or 4) by area averaging, in halving steps (OpenCV's fast path)."""
    from weather_gym.weather._area import area_shrink  # numba loads here

    for _ in range(f // 2):
        h, w = img.shape[:2]
        img = area_shrink(img, (max(w // 2, 1), max(h // 2, 1)))
    return img


def _zoom_blur(img: np.ndarray, scale: float) -> np.ndarray:
    """Average of the image magnified by factors from 1 to ``1 + scale`` (new array).

    Computed at half resolution, or quarter resolution when the smear is long anyway (> 16 px).
    """
    h, w = img.shape[:2]
    disp = scale * 0.5 * math.hypot(w, h)  # largest displacement, full-resolution pixels
    f = 4 if disp > 16 and min(h, w) >= 16 else 2
    small = _shrink(img, f)
    m = min(max(math.ceil(math.log2(disp / f + 1)), 1), 3)
    c = (1.0 + scale) ** (1.0 / (2 ** m - 1))
    acc = small
    for j in range(m):  # 2**m taps: scales c**i, i = 0 .. 2**m - 1
        acc = cv2.addWeighted(acc, 0.5, _zoom(acc, c ** (2 ** j)), 0.5, 0)
    return cv2.resize(acc, (w, h), interpolation=cv2.INTER_LINEAR)


def _hbox(img: np.ndarray, n: int, out: np.ndarray) -> np.ndarray:
    """Horizontal box of ``n`` px into ``out`` (``cv2.blur``, border replicated; its generic path is
    3x slower than its 3- and 5-tap ones, so 2 taps are an average of two shifted views)."""
    if n == 2 and img.shape[1] > 1:  # taps x - 1 and x, as cv2.blur anchors an even box
        into(cv2.addWeighted(img[:, :-1], 0.5, img[:, 1:], 0.5, 0, dst=out[:, 1:]), out[:, 1:])
        out[:, 0] = img[:, 0]
        return out
    return into(cv2.blur(img, (n, 1), dst=out, borderType=cv2.BORDER_REPLICATE), out)


_WEIGHT_CACHE: dict[tuple, np.ndarray] = {}


def _fallback_weight(key: tuple, who: str) -> np.ndarray:
    """The nearness weights of the flat-ground scene of ``key`` (cached)."""
    from weather_gym.weather._near_blend import near_weight

    wt = _WEIGHT_CACHE.get(key)
    if wt is None:
        h, w, fx, camera_height_m, horizon_frac, near_depth_m, far_m = key
        wt = readonly(near_weight(scene_depth(None, h, w, fx, camera_height_m, horizon_frac, far_m, who), near_depth_m))
        wt = _WEIGHT_CACHE.setdefault(key, wt)
        if len(_WEIGHT_CACHE) > 16:
            _WEIGHT_CACHE.pop(next(iter(_WEIGHT_CACHE)), None)
    return wt


MAX_SMEAR_WIDTHS = 4
"""Longest yaw smear, in frame widths (beyond that the frame is one uniform streak, and the box filter's
cost grows with its length)."""


def motion_smear(img: np.ndarray, depth: np.ndarray | None, state: dict[str, float], exposure_s: float, *,
                 speed_mps: float, yaw_rate_rps: float, hfov_deg: float, camera_height_m: float,
                 horizon_frac: float, near_depth_m: float, far_m: float, who: str,
                 out: np.ndarray | None = None) -> np.ndarray:
    """Blur ``img`` by the car's motion during ``exposure_s`` seconds.

    The result goes to ``out`` when given (and is returned); without ``out`` it is a new array, or
    ``img`` itself when there is no blur.
    """
    h, w = img.shape[:2]
    fx = focal_px(state, w, hfov_deg)
    speed = abs(state.get("speed", speed_mps))
    yaw = abs(state.get("yaw_rate", yaw_rate_rps))
    scale = speed * exposure_s / near_depth_m
    zoom = scale * 0.5 * math.hypot(w, h) >= 1.0
    length = fx * yaw * exposure_s
    if length > MAX_SMEAR_WIDTHS * w:
        raise LimitError(f"{who}: the yaw smear would be {length:.3g} px (fx {fx:.4g} px x yaw rate {yaw:.3g} rad/s "
                         f"x exposure {exposure_s:.3g} s) on a {w} px wide frame; at most {MAX_SMEAR_WIDTHS} frame "
                         "widths are supported")
    n = int(round(length)) if length >= 1.5 else 0
    src = img
    if zoom:  # img + (zoom blur - img) * w / 255, w from the nearness (compiled; numba loads here)
        from weather_gym.weather._near_blend import near_blend

        if depth is not None:
            depth_min(depth, who)  # finite metres >= 0
        blurred = _zoom_blur(img, scale)
        dst = out if out is not None and not n else np.empty_like(img)
        if depth is None:
            weight = _fallback_weight((h, w, fx, camera_height_m, horizon_frac, near_depth_m, far_m), who)
            near_blend(img, blurred, weight, None, dst)
        else:
            near_blend(img, blurred, depth, near_depth_m, dst)
        src = dst
    if n:
        dst = out if out is not None else np.empty_like(img)
        src = _hbox(src, n, dst)
    if out is not None and src is not out:
        np.copyto(out, src)
        return out
    return src


def smear_split(img: np.ndarray, depth: np.ndarray | None, state: dict[str, float], exposure_s: float, *,
                speed_mps: float, yaw_rate_rps: float, hfov_deg: float, camera_height_m: float,
                horizon_frac: float, near_depth_m: float, far_m: float, who: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`motion_smear` of ``img``'s luma at full resolution and of ``img`` at half resolution.

    Returns ``(luma, half)``: uint8 ``H x W`` (Rec. 601 luma) and ``ceil(H/2) x ceil(W/2) x 3``, both
    blurred by the car's motion during ``exposure_s`` (new arrays). One zoom blur serves both (made
    from the half-resolution frame at the resolution :func:`motion_smear` uses, its luma enlarged
    for the full-resolution blend); the yaw box is as long in each frame's own pixels.
    """
    h, w = img.shape[:2]
    hh, hw = (h + 1) // 2, (w + 1) // 2
    from weather_gym.weather._area import area_shrink  # numba loads here

    luma = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    half = area_shrink(img, (hw, hh))
    fx = focal_px(state, w, hfov_deg)
    speed = abs(state.get("speed", speed_mps))
    yaw = abs(state.get("yaw_rate", yaw_rate_rps))
    scale = speed * exposure_s / near_depth_m
    length = fx * yaw * exposure_s
    if length > MAX_SMEAR_WIDTHS * w:
        raise LimitError(f"{who}: the yaw smear would be {length:.3g} px (fx {fx:.4g} px x yaw rate {yaw:.3g} rad/s "
                         f"x exposure {exposure_s:.3g} s) on a {w} px wide frame; at most {MAX_SMEAR_WIDTHS} frame "
                         "widths are supported")
    if scale * 0.5 * math.hypot(w, h) >= 1.0:  # the zoom blur, blended by nearness
        from weather_gym.weather._near_blend import near_blend, near_weight

        disp = scale * 0.5 * math.hypot(w, h)
        f = 4 if disp > 16 and min(h, w) >= 16 else 2
        small = _shrink(half, f // 2) if f == 4 else half
        m = min(max(math.ceil(math.log2(disp / f + 1)), 1), 3)
        c = (1.0 + scale) ** (1.0 / (2 ** m - 1))
        acc = small
        for j in range(m):
            acc = cv2.addWeighted(acc, 0.5, _zoom(acc, c ** (2 ** j)), 0.5, 0)
        blurred_half = cv2.resize(acc, (hw, hh), interpolation=cv2.INTER_LINEAR) if acc.shape[:2] != (hh, hw) else acc
        blurred_luma = cv2.resize(cv2.cvtColor(acc, cv2.COLOR_RGB2GRAY), (w, h), interpolation=cv2.INTER_LINEAR)
        if depth is None:
            wt = _fallback_weight((h, w, fx, camera_height_m, horizon_frac, near_depth_m, far_m), who)
            wt_half = _fallback_weight((hh, hw, fx * hw / w, camera_height_m, horizon_frac, near_depth_m, far_m), who)
        else:
            wt = near_weight(depth, near_depth_m, who)  # checks the depths too (finite metres >= 0)
            if (h, w) == (2 * hh, 2 * hw):  # the nearest depth at exactly half is every other one's
                wt_half = np.ascontiguousarray(wt[::2, ::2])
            else:
                wt_half = near_weight(cv2.resize(np.ascontiguousarray(depth, np.float32), (hw, hh),
                                                 interpolation=cv2.INTER_NEAREST), near_depth_m)
        luma_out, half_out = np.empty_like(luma), np.empty_like(half)  # (new frames: numba vectorises the
        near_blend(luma, blurred_luma, wt, None, luma_out)              # blend only when out is not an input)
        near_blend(half, blurred_half, wt_half, None, half_out)
        luma, half = luma_out, half_out
    n = int(round(length)) if length >= 1.5 else 0
    if n:
        luma = _hbox(luma, n, np.empty_like(luma))
        n2 = int(round(length * hw / w)) if length * hw / w >= 1.5 else 0
        if n2:
            half = _hbox(half, n2, np.empty_like(half))
    return luma, half


@dataclass(frozen=True)
class CameraGeometry(KnobEffect):
    """Camera parameters used when the state or the depth map does not give them (not registered).

    ``hfov_deg`` gives the focal length when ``state['fx']`` is absent; without a depth map the
    scene is a flat ground plane ``camera_height_m`` below a level camera, horizon at
    ``horizon_frac`` of the image height and ``far_m`` at and above the horizon.
    """

    hfov_deg: float = DEFAULT_HFOV_DEG
    camera_height_m: float = 1.0
    horizon_frac: float = 0.5
    far_m: float = 200.0

    PARAM_LIMITS: ClassVar = {
        "hfov_deg": (5.0, 175.0),
        "camera_height_m": (0.05, 20.0),
        "horizon_frac": (0.0, 1.0),
        "far_m": (1.0, 1e5),
    }


@dataclass(frozen=True)
class EgoMotion(CameraGeometry):
    """Vehicle motion defaults (used when the state lacks ``speed`` / ``yaw_rate``), not registered."""

    speed_mps: float = 10.0
    yaw_rate_rps: float = 0.3
    near_depth_m: float = 2.0

    PARAM_LIMITS: ClassVar = {
        **CameraGeometry.PARAM_LIMITS,
        "speed_mps": (0.0, 150.0),
        "yaw_rate_rps": (0.0, 10.0),
        "near_depth_m": (0.5, 20.0),
    }

    def smear(self, img: np.ndarray, depth: np.ndarray | None, state: dict[str, float],
              exposure_s: float, out: np.ndarray | None = None) -> np.ndarray:
        """Motion blur of ``exposure_s`` seconds, into ``out`` when given (else may return ``img`` itself)."""
        return motion_smear(img, depth, state, exposure_s, speed_mps=self.speed_mps,
                            yaw_rate_rps=self.yaw_rate_rps, hfov_deg=self.hfov_deg,
                            camera_height_m=self.camera_height_m, horizon_frac=self.horizon_frac,
                            near_depth_m=self.near_depth_m, far_m=self.far_m, who=self.name, out=out)

    def smear_split(self, img: np.ndarray, depth: np.ndarray | None, state: dict[str, float],
                    exposure_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Motion blur of ``exposure_s`` seconds of the luma at full and the frame at half resolution
        (:func:`smear_split`)."""
        return smear_split(img, depth, state, exposure_s, speed_mps=self.speed_mps,
                           yaw_rate_rps=self.yaw_rate_rps, hfov_deg=self.hfov_deg,
                           camera_height_m=self.camera_height_m, horizon_frac=self.horizon_frac,
                           near_depth_m=self.near_depth_m, far_m=self.far_m, who=self.name)
