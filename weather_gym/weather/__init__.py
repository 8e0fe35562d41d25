"""Weather effects: cheap image degradations, each driven by one severity knob ``k`` in [0, 1].

No PyBullet here: the layer works on any uint8 RGB image stream (numpy + OpenCV; pydantic for the declared parameter schemas).

* ``EFFECTS`` / ``make(name, k=..., **params)``: the registry of effects (``EFFECTS.names()``; each
  module imported below registers its effect: a new effect is its file and its line there);
* ``Compose``: effects in order; ``Ramp``: k changing over an episode;
* ``parse_weather`` / ``to_spec``: weather specs; ``load_presets`` / ``preset_spec``: the
  condition x severity table.

Every effect: ``effect(image, *, depth=None, state=None, rng=None) -> new image`` and
``effect.reset(seed)``, built from ``effect.sample(rng, shape, episode) -> draw`` and a pure
``effect.render(image, draw)``; ``effect.start(seed)`` is an episode of its own
(:class:`EffectRun`); see :mod:`weather_gym.weather.base` and ``docs/weather.md``.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make, parse_weather
    >>> frame = np.full((376, 672, 3), 120, np.uint8)
    >>> weather = parse_weather({"droplets": 0.55, "dim": 0.3})
    >>> weather.reset(0)
    >>> weather(frame).shape
    (376, 672, 3)
"""

from __future__ import annotations

# importing an effect module registers it
from weather_gym.weather import (  # noqa: F401
    blur,
    dim,
    droplets,
    exposure,
    fog,
    glare,
    jpeg,
    motion_blur,
    noise,
    rain,
    vignette,
)
from weather_gym.weather.base import DEFAULT_SEED, STATE_KEYS, Effect, EffectRun, KnobEffect
from weather_gym.weather.blur import Blur
from weather_gym.weather.compose import Compose
from weather_gym.weather.dim import Dim
from weather_gym.weather.droplets import Droplets
from weather_gym.weather.exposure import Exposure
from weather_gym.weather.fog import Fog
from weather_gym.weather.glare import Glare
from weather_gym.weather.jpeg import Jpeg
from weather_gym.weather.motion_blur import MotionBlur
from weather_gym.weather.noise import Noise
from weather_gym.weather.presets import (
    PRESETS_ENV,
    SEVERITIES,
    load_presets,
    preset_entry,
    preset_source,
    preset_spec,
)
from weather_gym.weather.presets import __getattr__ as __getattr__  # CONDITIONS, ALIASES: from the registry
from weather_gym.weather.rain import Rain
from weather_gym.weather.registry import EFFECTS, make, register_effect
from weather_gym.weather.schedule import Ramp
from weather_gym.weather.spec import (
    WeatherSpec,
    current_spec,
    parse_weather,
    preset_items,
    to_spec,
    weather_source,
)
from weather_gym.weather.vignette import Vignette

__all__ = [
    "CONDITIONS", "DEFAULT_SEED", "EFFECTS", "PRESETS_ENV", "SEVERITIES", "STATE_KEYS",
    "Blur", "Compose", "Dim", "Droplets", "Effect", "EffectRun", "Exposure", "Fog", "Glare", "Jpeg", "KnobEffect",
    "MotionBlur", "Noise", "Rain", "Ramp", "Vignette", "WeatherSpec",
    "current_spec", "load_presets", "make", "parse_weather", "preset_entry", "preset_items", "preset_source", "preset_spec",
    "register_effect", "to_spec", "weather_source",
]
