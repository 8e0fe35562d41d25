"""Reinforcement learning on weather-gym: ``weather-gym train`` (:mod:`weather_gym.lab.training.policy.train`) and its
hyper-parameter file ``HYPERPARAMS`` (rl-zoo3's YAML format, read by ``python -m rl_zoo3.train`` too).

Example:
    >>> from weather_gym.lab.training.policy import HYPERPARAMS
    >>> HYPERPARAMS.name
    'ppo.yml'
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["HYPERPARAMS"]

HYPERPARAMS = Path(__file__).resolve().with_name("ppo.yml")
"""The shipped PPO hyper-parameters (rl-zoo3 format; section ``WeatherGym/ConeTrackCones-v0``)."""
