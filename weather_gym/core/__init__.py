"""Plumbing shared by every layer: the registry class, typed errors, safe output writing, limits, shipped
data paths, cone classes and per-frame arrays. It imports no layer.

Example:
    >>> from weather_gym.core.errors import InputError
    >>> from weather_gym.core.limits import parse_size
    >>> parse_size("672x376", what="--camera")
    (672, 376)
    >>> issubclass(InputError, ValueError)
    True
"""
