"""Bounds checked before any work starts, so that no input runs for minutes or exhausts memory.

Images a weather effect or the detector is given, and camera sizes the simulator renders, must
lie within these limits; effect parameters carry their own physical ranges
(declared on each effect). A value outside raises :class:`LimitError` naming it.

Example:
    >>> from weather_gym.core.limits import check_image_size
    >>> check_image_size((376, 672, 3))
    >>> check_image_size((1, 5000, 3), what="frame.png")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.LimitError: frame.png: image is 5000x1 pixels; each side must be 8 to 16384 pixels
"""

from __future__ import annotations

from collections.abc import Sequence

from weather_gym.core.errors import InputError, LimitError

__all__ = ["MIN_IMAGE_SIDE", "MAX_IMAGE_SIDE", "MAX_IMAGE_PIXELS", "MAX_CAMERA_SIDE", "MAX_SEED", "check_image_size",
           "check_seed", "parse_size", "parse_sizes"]

MIN_IMAGE_SIDE = 8
"""Smallest image side (pixels) an effect or the detector accepts."""
MAX_IMAGE_SIDE = 16384
"""Largest image side (pixels)."""
MAX_IMAGE_PIXELS = 40_000_000
"""Largest image area: 40 MP (8K UHD is 33 MP); a float32 working copy is then 480 MB."""
MAX_CAMERA_SIDE = 4096
"""Largest simulated camera side (pixels): rendering cost grows with the area."""
MAX_SEED = 2**63 - 1
"""Largest seed: NumPy's ``SeedSequence`` and Gymnasium take whole numbers 0..2**63-1 here."""


def check_seed(seed: object, *, what: str = "seed") -> int:
    """``seed`` as an int if it is a whole number in 0..:data:`MAX_SEED`, else :class:`LimitError` naming ``what``.

    Example:
        >>> check_seed(3)
        3
        >>> check_seed(-1, what="--seed")
        Traceback (most recent call last):
        ...
        weather_gym.core.errors.LimitError: --seed must be a whole number in 0..9223372036854775807, got -1
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise LimitError(f"{what} must be a whole number in 0..{MAX_SEED}, got {seed!r}")
    return seed


def check_image_size(shape: Sequence[int], *, what: str = "image", min_side: int = MIN_IMAGE_SIDE) -> None:
    """Refuse an image shape ``(H, W[, C])`` outside the limits (:class:`LimitError` naming ``what``).

    ``min_side``: the smallest side allowed (weather effects take any size from 1 pixel)."""
    h, w = int(shape[0]), int(shape[1])
    if not (min_side <= h <= MAX_IMAGE_SIDE and min_side <= w <= MAX_IMAGE_SIDE):
        raise LimitError(f"{what}: image is {w}x{h} pixels; each side must be {min_side} to "
                         f"{MAX_IMAGE_SIDE} pixels")
    if h * w > MAX_IMAGE_PIXELS:
        raise LimitError(f"{what}: image is {w}x{h} = {h * w / 1e6:.0f} MP; at most {MAX_IMAGE_PIXELS / 1e6:.0f} MP "
                         "are supported")


def parse_size(text: str, *, what: str, example: str = "672x376") -> tuple[int, int]:
    """``"WxH"`` -> ``(W, H)``, whole pixels >= 1 (the bounds are the caller's); InputError naming ``what``.

    Example:
        >>> parse_size("336x188", what="--camera")
        (336, 188)
        >>> parse_size("336by188", what="--camera")
        Traceback (most recent call last):
        ...
        weather_gym.core.errors.InputError: --camera must be WxH in pixels (e.g. 672x376), got '336by188'
    """
    w, sep, h = str(text).lower().partition("x")
    w, h = w.strip(), h.strip()
    if not (sep and w.isdigit() and h.isdigit() and int(w) >= 1 and int(h) >= 1):
        raise InputError(f"{what} must be WxH in pixels (e.g. {example}), got {text!r}")
    return int(w), int(h)


def parse_sizes(text: str, *, what: str, example: str = "336x188,672x376") -> list[tuple[int, int]]:
    """``"WxH,WxH,..."`` -> ``[(W, H), ...]`` (:func:`parse_size` of each item).

    Example:
        >>> parse_sizes("336x188, 672x376", what="--sizes")
        [(336, 188), (672, 376)]
    """
    return [parse_size(item, what=f"{what} {text!r}: each item", example=example) for item in str(text).split(",")]
