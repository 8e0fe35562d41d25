"""Appearance of the scene (light, ground, sky, cone shades, camera jitter), randomizable per episode.

A ``Look`` is plain data: the env applies it at ``reset(options={"look": ...})`` and datasets
record it so a view can be re-rendered exactly.

Example:
    >>> import numpy as np
    >>> from weather_gym.sim.look import DEFAULT_LOOK, sample_look, Look
    >>> a = sample_look(np.random.default_rng(1)); b = sample_look(np.random.default_rng(1))
    >>> a == b, Look.from_dict(a.to_dict()) == a
    (True, True)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError, check_known
from weather_gym.sim.ego import EGO_VARIANTS
from weather_gym.sim.scenery import CLUTTER_LAYOUTS

RGB = tuple[float, float, float]


@dataclass(frozen=True)
class Look:
    """Scene appearance. Colours are 0..255 RGB; ``cone_shade`` multiplies each class's colours.

    The last three fields only matter in the realistic scene (``SimConfig(scene="realistic")``):
    ``clutter_seed`` (track-side clutter layout, 0-63), ``clutter_tint`` (RGB multiplier of the
    clutter) and ``ego_seed`` (the ego car's overlay, 0-15; -1 = none).
    """

    light_direction: tuple[float, float, float] = (0.35, 0.25, 1.0)
    light_color: RGB = (1.0, 1.0, 1.0)
    ambient: float = 0.65
    diffuse: float = 0.40
    specular: float = 0.03
    asphalt_rgb: RGB = (96.0, 96.0, 100.0)
    grass_rgb: RGB = (74.0, 122.0, 58.0)
    kerb_rgb: RGB = (210.0, 210.0, 205.0)
    ground_seed: int = 0
    sky_top_rgb: RGB = (88.0, 132.0, 196.0)
    sky_horizon_rgb: RGB = (182.0, 200.0, 222.0)
    cloud_cover: float = 0.35
    sky_seed: int = 0
    cone_shade: tuple[RGB, RGB, RGB, RGB] = ((1.0, 1.0, 1.0),) * 4  # multipliers in (0, 1]
    camera_height_offset: float = 0.0
    camera_pitch_offset_deg: float = 0.0
    camera_yaw_offset_deg: float = 0.0
    # the realistic scene (SimConfig(scene="realistic")) only; the plain scene ignores these
    clutter_seed: int = 0
    clutter_tint: RGB = (1.0, 1.0, 1.0)
    ego_seed: int = -1

    def __post_init__(self) -> None:
        for f in fields(self):
            flat = np.asarray(getattr(self, f.name), dtype=np.float64).ravel()
            if not np.all(np.isfinite(flat)):
                raise InputError(f"look.{f.name} must be finite, got {getattr(self, f.name)!r}")
        if np.linalg.norm(self.light_direction) == 0:
            raise InputError("look.light_direction must not be the zero vector")
        if not (isinstance(self.clutter_seed, (int, np.integer)) and 0 <= self.clutter_seed < CLUTTER_LAYOUTS):
            raise InputError(f"look.clutter_seed must be an integer in [0, {CLUTTER_LAYOUTS}), got {self.clutter_seed!r}")
        if not (isinstance(self.ego_seed, (int, np.integer)) and -1 <= self.ego_seed < EGO_VARIANTS):
            raise InputError(f"look.ego_seed must be -1 (no ego car) or an integer in [0, {EGO_VARIANTS}), "
                             f"got {self.ego_seed!r}")
        if len(self.cone_shade) != 4:
            raise InputError(f"look.cone_shade needs one RGB multiplier per cone class (4), got {len(self.cone_shade)}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Look:
        """Build from a dict (e.g. JSON); unknown keys are an error naming them."""
        check_known(d, {f.name for f in fields(cls)}, what="look")
        conv: dict[str, Any] = {}
        for k, v in d.items():
            if k == "cone_shade":
                conv[k] = tuple(tuple(float(c) for c in rgb) for rgb in v)
            elif isinstance(v, (list, tuple)):
                conv[k] = tuple(float(c) for c in v)
            elif k.endswith("_seed"):
                conv[k] = int(v)
            else:
                conv[k] = float(v)
        return cls(**conv)


GROUND_STYLES: tuple[tuple[RGB, RGB], ...] = (
    ((96.0, 96.0, 100.0), (74.0, 122.0, 58.0)),
    ((72.0, 72.0, 76.0), (64.0, 110.0, 48.0)),
    ((120.0, 118.0, 116.0), (90.0, 130.0, 62.0)),
    ((84.0, 86.0, 92.0), (98.0, 118.0, 70.0)),
    ((108.0, 104.0, 98.0), (58.0, 96.0, 44.0)),
    ((64.0, 66.0, 70.0), (104.0, 140.0, 80.0)),
)
"""(asphalt, grass) colour pairs that ``sample_look`` draws from."""

DEFAULT_LOOK = Look()
"""Bright overcast: soft light, few shadows, high contrast (like the study's simulated ideal set)."""

REALISTIC_LOOK = Look(
    light_direction=(0.3, 0.45, 1.0), ambient=0.6, diffuse=0.45, specular=0.03,
    asphalt_rgb=(120.0, 120.0, 118.0), grass_rgb=(132.0, 130.0, 126.0), ground_seed=0,
    sky_top_rgb=(170.0, 190.0, 215.0), sky_horizon_rgb=(225.0, 230.0, 236.0), cloud_cover=0.7, sky_seed=1,
    clutter_seed=1, ego_seed=0,
)
"""The realistic scene's default: a bright overcast day on a paved paddock, the ego car in view
(``ConeTrackEnv`` uses it when ``SimConfig.scene == "realistic"`` and no look is given)."""


def _jitter_rgb(rng: np.random.Generator, base: RGB, rel: float) -> RGB:
    return tuple(float(np.clip(c * (1 + rng.uniform(-rel, rel)), 0, 255)) for c in base)  # type: ignore[return-value]  # three in, three out


def sample_look(rng: np.random.Generator) -> Look:
    """A random daylight look (domain randomization for detector training)."""
    az = rng.uniform(0, 2 * math.pi)
    el = rng.uniform(math.radians(25), math.radians(80))
    light_dir = (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))
    warm = rng.uniform(-1, 1)  # -1 cool, +1 warm
    light_color = (1.0 + 0.08 * warm, 1.0, 1.0 - 0.10 * warm)
    # the ground comes from a small palette: each distinct ground is a 2048^2 texture held by the world
    asphalt, grass = GROUND_STYLES[int(rng.integers(len(GROUND_STYLES)))]
    sky_top = _jitter_rgb(rng, (88.0, 132.0, 196.0), 0.2)
    sky_hor = _jitter_rgb(rng, (182.0, 200.0, 222.0), 0.1)
    shades = tuple(tuple(float(rng.uniform(0.8, 1.0)) for _ in range(3)) for _ in range(4))
    return Look(
        light_direction=tuple(float(v) for v in light_dir),  # type: ignore[arg-type]  # three floats
        light_color=light_color,
        ambient=float(rng.uniform(0.45, 0.75)),
        diffuse=float(rng.uniform(0.25, 0.6)),
        specular=float(rng.uniform(0.0, 0.15)),
        asphalt_rgb=asphalt,
        grass_rgb=grass,
        kerb_rgb=(210.0, 210.0, 205.0),
        ground_seed=int(rng.integers(0, 2)),
        sky_top_rgb=sky_top,
        sky_horizon_rgb=sky_hor,
        cloud_cover=float(rng.uniform(0.0, 0.8)),
        sky_seed=int(rng.integers(0, 2**31 - 1)),
        cone_shade=shades,  # type: ignore[arg-type]  # 4 x 3 floats
        camera_height_offset=float(rng.uniform(-0.05, 0.05)),
        camera_pitch_offset_deg=float(rng.uniform(-1.5, 1.5)),
        camera_yaw_offset_deg=float(rng.uniform(-1.0, 1.0)),
    )
