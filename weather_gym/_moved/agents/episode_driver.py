"""Deprecated alias of :mod:`weather_gym.pipeline.episode` (goes in weather-gym 0.3)."""

from weather_gym.core.moved import alias_module

alias_module(__name__)
