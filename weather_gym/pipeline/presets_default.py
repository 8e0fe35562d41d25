"""What ``CONDITION@SEVERITY`` means in an env built here: by default, resolved for the env's scenario.

A calibrated preset names a damage (``low_light@2``: the detector keeps 0.344 of its clear mAP, as at
dusk in the study). An env built by :func:`~weather_gym.pipeline.make_env` or ``gym.make`` with such a
weather and no ``presets=`` reads the presets resolved for its track, world, camera, camera model and the
detector in the loop (the shipped one where the agent sees images or another perception runs): the
calibration lab's :func:`~weather_gym.lab.calibration.resolve.presets_for_env` (cached on disk: minutes the
first time a scenario is used, milliseconds after). ``WEATHER_GYM_PRESETS=pool`` keeps the shipped pool
presets; ``WEATHER_GYM_PRESETS=FILE`` or ``presets=FILE`` a file; explicit ``NAME:K`` weather never changes.

The lab sits above this layer, so the resolver is named here (:data:`RESOLVER`) and imported when
needed, as Gymnasium's ids name their entry point (``weather_gym.envs.registration.ENTRY_POINT``).

Example:
    >>> RESOLVER
    'weather_gym.lab.calibration.resolve:presets_for_env'
"""

from __future__ import annotations

import importlib
from typing import Any

from weather_gym.weather import preset_items
from weather_gym.weather.presets import presets_meaning

__all__ = ["RESOLVER", "default_presets"]

RESOLVER = "weather_gym.lab.calibration.resolve:presets_for_env"
"""``module:function`` ``(spec, config, detector) -> presets file or None`` that resolves a preset for an env."""


def default_presets(spec: Any, config: Any, detector: Any = None, *, force: bool = False) -> str | None:
    """The presets file ``spec``'s presets read in an env of ``config`` (an ``EnvConfig``) with ``detector``
    in the loop when no ``presets=`` is given: None (the weather layer's default: ``$WEATHER_GYM_PRESETS``
    or the pool presets) unless the default meaning is ``resolved`` (or ``force``) and ``spec`` names a preset."""
    if spec is None or not (force or presets_meaning() == "resolved") or not preset_items(spec):
        return None
    module, _, name = RESOLVER.partition(":")
    resolver = getattr(importlib.import_module(module), name)
    path = resolver(spec, config, detector)
    return None if path is None else str(path)
