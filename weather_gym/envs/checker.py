"""Gymnasium's passive env checker, made safe for a refused first ``reset``.

``gymnasium.wrappers.PassiveEnvChecker`` marks its one-time reset check as done *before* it calls the
env's ``reset``. When that first reset refuses an option (a typed error, as every reset option is
checked), the mark stays and the checker keeps no reset result; the first ``step`` after the next,
valid reset then fails inside Gymnasium (``TypeError: cannot unpack non-iterable NoneType object``).
:class:`PassiveEnvCheckerSafeReset` is that checker, except that a first reset which raises leaves the
check to run on the next reset. The registered ids use it in place of Gymnasium's (the same place:
around what the entry point returns); see :mod:`weather_gym.envs.registration`.

Example:
    >>> import gymnasium as gym
    >>> env = PassiveEnvCheckerSafeReset(gym.make("CartPole-v1", disable_env_checker=True))
    >>> try:
    ...     env.reset(seed="bad")             # refused before anything was checked
    ... except Exception as exc:
    ...     print(type(exc).__name__)
    Error
    >>> env.checked_reset                     # the check runs again on the next reset
    False
    >>> _ = env.reset(seed=0); _ = env.step(0)
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

__all__ = ["PassiveEnvCheckerSafeReset"]


class PassiveEnvCheckerSafeReset(gym.wrappers.PassiveEnvChecker):
    """:class:`gymnasium.wrappers.PassiveEnvChecker` whose check of the first reset survives a refused reset."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        first = not self.checked_reset
        try:
            return super().reset(seed=seed, options=options)
        except BaseException:
            if first:  # nothing was checked: the next reset is the first
                self.checked_reset = False
                self._previous_data = None
            raise
