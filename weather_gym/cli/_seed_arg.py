"""The seed options (``--seed N``, ``--seeds A,B,...``): whole numbers 0..2**63-1, checked when parsed.

A negative or huge seed is an ``error: argument --seed: ...`` (exit status 2) before anything
runs, never NumPy's own ``ValueError`` from deep inside a run.

Example:
    >>> seed_arg("7")
    7
"""

from __future__ import annotations

import argparse

from weather_gym.core.errors import InputError
from weather_gym.core.limits import check_seed


def seed_arg(text: str) -> int:
    """argparse ``type=`` of a seed option."""
    try:
        return check_seed(int(text), what="the seed")
    except ValueError as exc:  # not a whole number, or out of range (LimitError is a ValueError)
        raise argparse.ArgumentTypeError(str(exc) if isinstance(exc, InputError) else
                                         f"expected a whole number >= 0, got {text!r}") from None


def int_list(text: str, what: str) -> list[int]:
    """Comma-separated whole numbers of the option ``what`` (InputError naming it)."""
    try:
        out = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{what}: expected comma-separated whole numbers, got {text!r}") from None
    if not out:
        raise InputError(f"{what}: no value given")
    return out


def seed_list(text: str, what: str) -> list[int]:
    """Comma-separated seeds of the option ``what`` (InputError naming it)."""
    out = int_list(text, what)
    for s in out:
        check_seed(s, what=what)
    return out
