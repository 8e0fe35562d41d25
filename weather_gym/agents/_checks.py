"""Validation shared by the agents' frozen config dataclasses (errors name the field and value).

Example:
    >>> from dataclasses import dataclass
    >>> from weather_gym.agents._checks import check_fields
    >>> @dataclass(frozen=True)
    ... class C:
    ...     gain: float = -1.0
    ...     def __post_init__(self): check_fields(self, positive=("gain",))
    >>> C()
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: C.gain must be a finite number > 0, got -1.0
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError


def check_fields(obj, *, positive: Iterable[str] = (), non_negative: Iterable[str] = (),
                 integers: Iterable[str] = ()) -> None:
    """Raise ``ValueError`` unless the named fields are finite numbers > 0, >= 0, or integers >= 1."""
    kind = type(obj).__name__
    for names, ok, what in ((positive, lambda v: v > 0, "a finite number > 0"),
                            (non_negative, lambda v: v >= 0, "a finite number >= 0")):
        for name in names:
            v = getattr(obj, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and ok(v)):
                raise InputError(f"{kind}.{name} must be {what}, got {v!r}")
    for name in integers:
        v = getattr(obj, name)
        if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
            raise InputError(f"{kind}.{name} must be an integer >= 1, got {v!r}")


def check_action(action: Any, who: str = "agent") -> np.ndarray:
    """Validate an agent's output: a finite float32 ``(2,)`` array in [-1, 1] (nothing is clamped)."""
    a = np.asarray(action, dtype=np.float32)
    if a.shape != (2,):
        raise InputError(f"{who} returned an action of shape {a.shape}; expected (2,) = (steering, throttle/brake)")
    if not np.isfinite(a).all() or (np.abs(a) > 1.0).any():
        raise InputError(f"{who} returned {a.tolist()}; both components must be finite and in [-1, 1]")
    return a
