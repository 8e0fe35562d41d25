"""The check of an agent's output (the agents' configs declare their fields' ranges:
:mod:`weather_gym.core.schema`).

Example:
    >>> check_action([0.5, -1.0]).tolist()
    [0.5, -1.0]
    >>> check_action([0.0, 2.0], "pure_pursuit")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: pure_pursuit returned [0.0, 2.0]; both components must be finite and in [-1, 1]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from weather_gym.core.errors import InputError


def check_action(action: Any, who: str = "agent") -> np.ndarray:
    """Validate an agent's output: a finite float32 ``(2,)`` array in [-1, 1] (nothing is clamped)."""
    a = np.asarray(action, dtype=np.float32)
    if a.shape != (2,):
        raise InputError(f"{who} returned an action of shape {a.shape}; expected (2,) = (steering, throttle/brake)")
    if not np.isfinite(a).all() or (np.abs(a) > 1.0).any():
        raise InputError(f"{who} returned {a.tolist()}; both components must be finite and in [-1, 1]")
    return a
