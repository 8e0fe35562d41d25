"""Formula Student cone classes and sizes (FS rules: small cone 228 x 228 x 325 mm, big 285 x 285 x 505 mm).

Example:
    >>> from weather_gym.core.cone_spec import CONE_CLASSES, cone_height
    >>> CONE_CLASSES.index("yellow"), cone_height("big_orange")
    (1, 0.505)
"""

from __future__ import annotations

from weather_gym.core.errors import InputError

CONE_CLASSES: tuple[str, ...] = ("blue", "yellow", "orange", "big_orange")
"""Class id = index in this tuple; COCO category id = index + 1."""

UNKNOWN_CLASS = -1
"""The class id of a cone whose colour is not known (a LiDAR's cone: shape, no colour)."""

CONE_HEIGHT_M: dict[str, float] = {"blue": 0.325, "yellow": 0.325, "orange": 0.325, "big_orange": 0.505}
CONE_BASE_M: dict[str, float] = {"blue": 0.228, "yellow": 0.228, "orange": 0.228, "big_orange": 0.285}

# RGB of the cone bodies and their stripe (sRGB, 0..1)
CONE_BODY_RGB: dict[str, tuple[float, float, float]] = {
    "blue": (0.05, 0.22, 0.80),
    "yellow": (0.98, 0.80, 0.05),
    "orange": (1.00, 0.42, 0.02),
    "big_orange": (1.00, 0.42, 0.02),
}
CONE_STRIPE_RGB: dict[str, tuple[float, float, float]] = {
    "blue": (0.95, 0.95, 0.95),
    "yellow": (0.08, 0.08, 0.08),
    "orange": (0.95, 0.95, 0.95),
    "big_orange": (0.95, 0.95, 0.95),
}


def class_id(name: str) -> int:
    """Class id of a colour tag; ``ValueError`` names the valid tags."""
    try:
        return CONE_CLASSES.index(name)
    except ValueError:
        raise InputError(f"unknown cone colour {name!r}; expected one of {', '.join(CONE_CLASSES)}") from None


def cone_height(name_or_id: str | int) -> float:
    name = CONE_CLASSES[name_or_id] if isinstance(name_or_id, int) else name_or_id
    return CONE_HEIGHT_M[name]
