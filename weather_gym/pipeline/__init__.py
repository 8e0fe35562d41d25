"""The pipeline layer: the builder (env -> weather -> perception), the perception modes and the episode driver.

``builder``: :func:`make_env` / :func:`make_vec_env` / :func:`make_scenario_env` (the entry point of every
registered id); ``modes``: :data:`PERCEPTION_MODES`, what an agent observes; ``episode``: :func:`run_episode`,
the one loop that drives an agent through an episode and returns an :class:`EpisodeResult`.

Example:
    >>> from weather_gym.pipeline import make_env, run_episode
    >>> from weather_gym.agents import make_agent
    >>> env = make_env(perception="gt_cones", max_episode_steps=50)
    >>> agent = make_agent("gt_pure_pursuit", env.unwrapped.track, env.unwrapped.config.camera)
    >>> result = run_episode(env, agent, seed=0)
    >>> result.steps, result.end_reason
    (50, 'time_limit')
    >>> env.close()
"""

from weather_gym.pipeline.builder import (
    DEFAULT_ENV_ID,
    MAX_SYNC_ENVS,
    make_env,
    make_scenario_env,
    make_vec_env,
    start_method,
    wrap_pipeline,
)
from weather_gym.pipeline.episode import EpisodeResult, run_episode
from weather_gym.pipeline.modes import PERCEPTION_MODES, PerceptionMode, register_mode

__all__ = ["DEFAULT_ENV_ID", "MAX_SYNC_ENVS", "PERCEPTION_MODES", "EpisodeResult", "PerceptionMode", "make_env",
           "make_scenario_env", "make_vec_env", "register_mode", "run_episode", "start_method", "wrap_pipeline"]
