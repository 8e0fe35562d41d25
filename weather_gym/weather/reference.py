"""Faithful ports of the reference study's two augmentations, kept as baselines.

They are slow on purpose: the tests check the fast effects against them byte for byte, and
``weather-gym bench weather`` times them side by side with the fast effects.

* :func:`study_droplets` — the study's "adherent droplets": Albumentations ``RandomFog`` as it was
  from version 0.3 to 1.4.15 (``get_params_dependent_on_targets`` + ``functional.add_fog``), with the
  final ``cv2.blur`` removed as the study did, ``fog_coef_lower = fog_coef_upper = 0.4`` and
  ``alpha_coef = k``. Each disc is drawn on a full-image copy and blended with ``cv2.addWeighted``
  exactly as the original did.
* :func:`study_dim` — ``PIL.ImageEnhance.Brightness(image).enhance(1 - k)`` with the array
  conversions a numpy pipeline pays for.

The droplet code is a port of Albumentations (https://github.com/albumentations-team/albumentations,
MIT licence, Copyright (c) 2017 Alexander Buslaev, Alex Parinov, Vladimir Iglovikov, Eugene
Khvedchenya and contributors), which took it from the Automold road augmentation library
(Ujjwal Saxena, MIT licence). Two deliberate differences, both documented in ``docs/weather.md``:
random numbers come from a ``numpy.random.Generator`` (x then y coordinates of a round, inclusive
bounds as Python's ``random.randint``) instead of the global ``random`` module, and a round whose
box cannot grow any more (tiny images, where the original loops forever) grows by one pixel.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather.reference import fog_layout
    >>> hw, radius, centres = fog_layout(376, 672, 0.4, np.random.default_rng(0))
    >>> hw, radius, len(centres)
    (89, 44, 24)
"""

from __future__ import annotations

import cv2
import numpy as np
from PIL import Image, ImageEnhance

__all__ = ["STUDY_FOG_COEF", "fog_layout", "study_dim", "study_droplets", "study_fog_positions"]

#: ``fog_coef_lower = fog_coef_upper`` used by the study (its Table 1).
STUDY_FOG_COEF = 0.4


def study_fog_positions(height: int, width: int, fog_coef: float,
                        rng: np.random.Generator) -> list[tuple[int, int]]:
    """``RandomFog.get_params_dependent_on_targets``: top-left corners of the haze discs."""
    imshape = (height, width)
    hw = max(1, int(width // 3 * fog_coef))

    haze_list: list[tuple[int, int]] = []
    midx = width // 2 - 2 * hw
    midy = height // 2 - hw
    index = 1

    while midx > -hw or midy > -hw:
        n = hw // 10 * index
        xs = rng.integers(midx, width - midx - hw, size=n, endpoint=True)
        ys = rng.integers(midy, height - midy - hw, size=n, endpoint=True)
        haze_list.extend(zip(xs.tolist(), ys.tolist(), strict=True))

        # at least one pixel per round: the original never terminates on tiny images
        midx -= max(3 * hw * width // sum(imshape), 1)
        midy -= max(3 * hw * height // sum(imshape), 1)
        index += 1

    return haze_list


def fog_layout(height: int, width: int, fog_coef: float,
               rng: np.random.Generator) -> tuple[int, int, list[tuple[int, int]]]:
    """``(hw, radius, centres)`` of the discs ``add_fog`` draws for one image.

    ``add_fog`` sizes discs with ``hw = max(int(width // 3 * fog_coef), 10)`` (positions were drawn
    with ``max(1, ...)``), draws each of radius ``hw // 2`` centred at ``(x + hw // 2, y + hw // 2)``.
    """
    hw = max(int(width // 3 * fog_coef), 10)
    centres = [(x + hw // 2, y + hw // 2) for x, y in study_fog_positions(height, width, fog_coef, rng)]
    return hw, hw // 2, centres


def study_droplets(image: np.ndarray, k: float, rng: np.random.Generator,
                   fog_coef: float = STUDY_FOG_COEF) -> np.ndarray:
    """The study's droplets: ``add_fog(img, fog_coef, alpha_coef=k, haze_list)`` without the blur."""
    img = image
    _, rad, centres = fog_layout(img.shape[0], img.shape[1], fog_coef, rng)
    alpha = k * fog_coef
    for point in centres:
        overlay = img.copy()
        output = img.copy()
        cv2.circle(overlay, point, int(rad), (255, 255, 255), -1)
        cv2.addWeighted(overlay, alpha, output, 1 - alpha, 0, output)
        img = output.copy()
    return img  # the study removed: cv2.blur(img, (hw // 10, hw // 10))


def study_dim(image: np.ndarray, k: float) -> np.ndarray:
    """The study's light dimming: Pillow's brightness enhancement with factor ``1 - k``."""

    return np.asarray(ImageEnhance.Brightness(Image.fromarray(image)).enhance(1.0 - k))
