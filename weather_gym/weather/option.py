"""The one weather option of every command: ``--weather SPEC`` (the CLI and the bench commands).

Argparse only (no other layer), so ``cli`` and ``bench`` both use it.

SPEC is the string ``WeatherWrapper`` and the presets take (:mod:`weather_gym.weather.spec`):
``NAME:K[:PARAM=VALUE...]`` (``droplets:0.5:mode=refractive``), a preset ``CONDITION@SEVERITY``
(``low_light@2``), several joined by commas (``droplets:0.55,dim:0.3``), ``clear``, or a JSON
list of ``{name, k, ...}`` tables. Commands that vary k themselves (sweeps) take the same strings
with k left open (``droplets,dim:k:mode=physical``) and the values in ``--k-grid``.

Example:
    >>> import argparse
    >>> parser = argparse.ArgumentParser()
    >>> add_weather_arg(parser)
    >>> parser.parse_args(["--weather", "droplets:0.5:mode=refractive"]).weather
    'droplets:0.5:mode=refractive'
    >>> weather_from_arg("low_light@2").name
    'dim'
"""

from __future__ import annotations

import json
from typing import Any

from weather_gym.core.errors import InputError
from weather_gym.weather.base import Effect
from weather_gym.weather.spec import parse_weather

__all__ = ["OPEN_K_GRAMMAR", "WEATHER_GRAMMAR", "add_weather_arg", "weather_from_arg"]

#: What ``--weather`` takes, for help texts.
WEATHER_GRAMMAR = ("NAME:K[:PARAM=VALUE...] (e.g. droplets:0.5:mode=refractive), a preset CONDITION@SEVERITY "
                   "(low_light@2), several joined by commas (droplets:0.55,dim:0.3), 'clear', or a JSON list of "
                   "{name, k, ...} tables")
#: What ``--weather`` takes where the command varies k.
OPEN_K_GRAMMAR = ("the same spec with k left open: NAME or NAME:k[:PARAM=VALUE...], several joined by commas "
                  "(e.g. droplets,dim:k:mode=physical)")


def add_weather_arg(p: Any, *, help: str = "weather applied to the images", **kwargs: Any) -> None:
    """Add ``--weather SPEC`` to the parser ``p`` (``kwargs``: ``default``, ``required``, ...)."""
    p.add_argument("--weather", metavar="SPEC", help=f"{help}: {WEATHER_GRAMMAR}", **kwargs)


def weather_from_arg(text: str | None, option: str = "--weather", presets: Any = None) -> Effect | None:
    """The effect of a ``--weather`` value (None stays None); errors name the option and the bad part.
    ``presets``: the presets file ``CONDITION@SEVERITY`` reads (None: ``$WEATHER_GYM_PRESETS``, else the shipped one)."""
    if text is None:
        return None
    stripped = text.strip()
    if stripped[:1] in ("[", "{"):
        try:
            return parse_weather(json.loads(stripped), presets)
        except json.JSONDecodeError as exc:
            raise InputError(f"{option} {text!r}: not valid JSON ({exc.msg})") from None
    return parse_weather(stripped, presets)
