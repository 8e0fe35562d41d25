"""Gymnasium environments: ``ConeTrackEnv`` and the scenarios registered from ``envs/*.toml``."""

from weather_gym.envs.cone_track import RESET_OPTIONS, STATE_FIELDS, ConeTrackEnv
from weather_gym.envs.config import EnvConfig, RewardConfig

__all__ = ["ConeTrackEnv", "EnvConfig", "RewardConfig", "STATE_FIELDS", "RESET_OPTIONS"]
