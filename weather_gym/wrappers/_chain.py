"""Walking a wrapper chain: the first wrapper of a given class between an env and its unwrapped core.

Example:
    >>> import gymnasium as gym
    >>> env = gym.wrappers.TimeLimit(gym.make("CartPole-v1").unwrapped, 10)
    >>> find_wrapper(env, gym.wrappers.TimeLimit) is env, find_wrapper(env, gym.wrappers.RecordEpisodeStatistics)
    (True, None)
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

__all__ = ["find_wrapper"]


def find_wrapper(env: gym.Env, cls: type) -> Any:
    """The outermost wrapper of ``env``'s chain that is a ``cls`` (None when there is none)."""
    e: Any = env
    while isinstance(e, gym.Wrapper):
        if isinstance(e, cls):
            return e
        e = e.env
    return None
