"""Domain randomisation for training data: the ranges (``RandomizeRanges``) and one draw of the
realistic world's appearance and camera from them (:func:`sample_realistic`).

Each field of ``RandomizeRanges`` is a ``(low, high)`` pair drawn uniformly (probabilities are single
numbers). ``weather-gym dataset render --randomize`` uses the defaults; ``--randomize-ranges FILE.toml``
and ``--randomize-set key=low,high`` override them (a bad key or range is an ``InputError`` naming it).

Example:
    >>> import numpy as np
    >>> from weather_gym.sim.randomize import RandomizeRanges, sample_realistic
    >>> r = RandomizeRanges().override({"exposure_ev": "-1,0.5"})
    >>> r.exposure_ev
    (-1.0, 0.5)
    >>> a = sample_realistic(np.random.default_rng(3), r); b = sample_realistic(np.random.default_rng(3), r)
    >>> a == b and -1.0 <= a.camera_model.exposure_ev <= 0.5
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Annotated

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel
from weather_gym.core._toml import read_toml
from weather_gym.core.errors import FileFormatError, InputError, check_known
from weather_gym.core.schema import Interval, Share, check_fields
from weather_gym.sim.ego import EGO_VARIANTS
from weather_gym.sim.look import Look
from weather_gym.sim.scenery import CLUTTER_LAYOUTS

Range = tuple[float, float]

_PROBABILITIES = ("p_ego", "p_grass", "p_jpeg")

ASPHALT_PALETTE: tuple[tuple[float, float, float], ...] = (
    (96.0, 96.0, 100.0), (120.0, 120.0, 118.0), (140.0, 138.0, 134.0), (78.0, 78.0, 82.0), (110.0, 106.0, 100.0),
    (128.0, 128.0, 132.0))
"""Asphalt colours (a small palette: each is a texture PyBullet keeps for the life of the process)."""
GRASS_PALETTE: tuple[tuple[float, float, float], ...] = (
    (74.0, 122.0, 58.0), (96.0, 118.0, 66.0), (64.0, 104.0, 50.0))
LOT_PALETTE: tuple[tuple[float, float, float], ...] = (
    (132.0, 130.0, 126.0), (150.0, 146.0, 138.0), (112.0, 112.0, 114.0))
"""Run-off that is not grass: gravel or a paved paddock (as at Estoril)."""


@dataclass(frozen=True)
class RandomizeRanges:
    """Ranges of the realistic world's domain randomisation (``(low, high)``, uniform), each inside the
    bounds its annotation declares (a range outside makes no physical sense here)."""

    sun_elevation_deg: Annotated[Range, Interval(1.0, 90.0)] = (15.0, 75.0)
    sun_azimuth_deg: Annotated[Range, Interval(-360.0, 720.0)] = (0.0, 360.0)
    light_warmth: Annotated[Range, Interval(-1.0, 1.0)] = (-1.0, 1.0)
    ambient: Annotated[Range, Interval(0.0, 1.5)] = (0.45, 0.8)
    diffuse: Annotated[Range, Interval(0.0, 1.5)] = (0.25, 0.7)
    specular: Annotated[Range, Interval(0.0, 1.0)] = (0.0, 0.1)
    cone_shade: Annotated[Range, Interval(0.3, 1.0)] = (0.75, 1.0)
    cloud_cover: Annotated[Range, Interval(0.0, 1.0)] = (0.2, 1.0)
    sky_brightness: Annotated[Range, Interval(0.5, 1.5)] = (0.85, 1.25)
    clutter_tint: Annotated[Range, Interval(0.3, 1.5)] = (0.75, 1.1)
    camera_height_offset: Annotated[Range, Interval(-0.8, 1.0)] = (-0.1, 0.3)
    camera_pitch_offset_deg: Annotated[Range, Interval(-15.0, 15.0)] = (-2.0, 8.0)
    camera_yaw_offset_deg: Annotated[Range, Interval(-10.0, 10.0)] = (-2.0, 2.0)
    hfov_deg: Annotated[Range, Interval(30.0, 140.0)] = (55.0, 95.0)
    exposure_ev: Annotated[Range, Interval(-4.0, 4.0)] = (-1.0, 2.0)
    white_balance: Annotated[Range, Interval(0.5, 2.0)] = (0.88, 1.12)
    contrast: Annotated[Range, Interval(0.5, 2.0)] = (0.85, 1.35)
    vignetting: Annotated[Range, Interval(0.0, 0.8)] = (0.0, 0.4)
    k1: Annotated[Range, Interval(-0.3, 0.3)] = (-0.10, 0.02)
    defocus_px: Annotated[Range, Interval(0.0, 3.0)] = (0.0, 1.0)
    read_noise: Annotated[Range, Interval(0.0, 20.0)] = (0.5, 4.0)
    shot_noise: Annotated[Range, Interval(0.0, 8.0)] = (0.5, 4.0)
    jpeg_quality: Annotated[Range, Interval(10.0, 100.0)] = (70.0, 95.0)
    p_ego: Share = 0.7
    p_grass: Share = 0.35
    p_jpeg: Share = 0.7

    def __post_init__(self) -> None:
        check_fields(self, who="randomize")

    def override(self, values: dict) -> RandomizeRanges:
        """A copy with ``values`` replaced: ``{key: (lo, hi) | "lo,hi" | p}``; unknown keys name the valid ones."""
        check_known(values, {f.name for f in fields(self)}, what="randomize")
        conv = {}
        for k, v in values.items():
            if isinstance(v, str):
                try:
                    parts = [float(x) for x in v.split(",")]
                except ValueError:
                    raise InputError(f"randomize.{k}: expected numbers like 'low,high', got {v!r}") from None
                v = parts[0] if k in _PROBABILITIES and len(parts) == 1 else tuple(parts)
            elif isinstance(v, list):
                v = tuple(v)
            conv[k] = v
        return replace(self, **conv)

    @classmethod
    def from_toml(cls, path: str | Path) -> RandomizeRanges:
        """Ranges from a TOML file of ``key = [low, high]`` (and ``p_* = probability``) lines."""
        path = Path(path)
        data = read_toml(path, "randomize ranges file")
        try:
            return cls().override(data)
        except InputError as exc:
            raise FileFormatError(f"{path}: {exc}") from None

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class RealisticDraw:
    """One draw: the ``look``, the ``camera_model`` and the camera's horizontal field of view."""

    look: Look
    camera_model: CameraModel
    hfov_deg: float

    def camera(self, base: CameraConfig) -> CameraConfig:
        return base if self.hfov_deg == base.hfov_deg else replace(base, hfov_deg=self.hfov_deg)


def _u(rng: np.random.Generator, r: Range) -> float:
    return float(rng.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])


def sample_realistic(rng: np.random.Generator, ranges: RandomizeRanges | None = None) -> RealisticDraw:
    """One random realistic appearance + camera pipeline (all from ``rng``)."""
    r = ranges or RandomizeRanges()
    el, az = math.radians(_u(rng, r.sun_elevation_deg)), math.radians(_u(rng, r.sun_azimuth_deg))
    warm = _u(rng, r.light_warmth)
    grass = rng.random() < r.p_grass
    runoff = GRASS_PALETTE[int(rng.integers(len(GRASS_PALETTE)))] if grass else \
        LOT_PALETTE[int(rng.integers(len(LOT_PALETTE)))]
    bright = _u(rng, r.sky_brightness)
    sky_top = tuple(float(min(255.0, c * bright)) for c in (150.0, 175.0, 210.0))
    sky_hor = tuple(float(min(255.0, c * bright)) for c in (215.0, 222.0, 230.0))
    tint = _u(rng, r.clutter_tint)
    look = Look(
        light_direction=(math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)),
        light_color=(1.0 + 0.08 * warm, 1.0, 1.0 - 0.10 * warm),
        ambient=_u(rng, r.ambient), diffuse=_u(rng, r.diffuse), specular=_u(rng, r.specular),
        asphalt_rgb=ASPHALT_PALETTE[int(rng.integers(len(ASPHALT_PALETTE)))],
        grass_rgb=runoff,
        ground_seed=int(rng.integers(0, 2)),
        sky_top_rgb=sky_top,  # type: ignore[arg-type]  # three floats
        sky_horizon_rgb=sky_hor,  # type: ignore[arg-type]  # three floats
        cloud_cover=_u(rng, r.cloud_cover),
        sky_seed=int(rng.integers(0, 2**31 - 1)),
        cone_shade=tuple(tuple(_u(rng, r.cone_shade) for _ in range(3)) for _ in range(4)),  # type: ignore[arg-type]  # 4 x 3 floats
        camera_height_offset=_u(rng, r.camera_height_offset),
        camera_pitch_offset_deg=_u(rng, r.camera_pitch_offset_deg),
        camera_yaw_offset_deg=_u(rng, r.camera_yaw_offset_deg),
        clutter_seed=int(rng.integers(0, CLUTTER_LAYOUTS)),
        clutter_tint=(tint * _u(rng, (0.9, 1.1)), tint, tint * _u(rng, (0.9, 1.1))),
        ego_seed=int(rng.integers(0, EGO_VARIANTS)) if rng.random() < r.p_ego else -1,
    )
    wb = _u(rng, r.white_balance)
    model = CameraModel(
        enabled=True, exposure_ev=_u(rng, r.exposure_ev), white_balance=(wb, 1.0, 1.0 / wb),
        contrast=_u(rng, r.contrast), vignetting=_u(rng, r.vignetting), k1=_u(rng, r.k1),
        defocus_px=_u(rng, r.defocus_px), read_noise=_u(rng, r.read_noise), shot_noise=_u(rng, r.shot_noise),
        chroma_subsampling=True,
        jpeg_quality=int(round(_u(rng, r.jpeg_quality))) if rng.random() < r.p_jpeg else 0,
    )
    return RealisticDraw(look=look, camera_model=model, hfov_deg=_u(rng, r.hfov_deg))
