"""Any weather spec as an Albumentations transform, so that the calibrated presets drop into a team's
training pipeline (the ``augment`` extra: ``pip install 'weather-gym[augment]'``).

Each call draws a new realisation of the weather (its drops, its noise) from the transform's own
generator, which ``A.Compose(..., seed=N)`` seeds: the same seed gives the same bytes. Images are
RGB uint8 ``(H, W, 3)``, Albumentations' own convention.

Example:
    >>> import albumentations as A
    >>> import numpy as np
    >>> from weather_gym.weather.augment import Weather
    >>> pipeline = A.Compose([A.HorizontalFlip(p=0.5), Weather("droplets@3", p=0.8)], seed=0)
    >>> pipeline(image=np.full((376, 672, 3), 120, np.uint8))["image"].shape
    (376, 672, 3)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from weather_gym.core.errors import InputError, MissingDependencyError
from weather_gym.weather.spec import parse_weather

try:
    import albumentations as A
except ImportError as _exc:  # pragma: no cover - the extra is not installed
    raise MissingDependencyError("weather_gym.weather.augment needs Albumentations: "
                                 "pip install 'weather-gym[augment]'") from _exc

__all__ = ["Weather"]


class Weather(A.ImageOnlyTransform):
    """The weather of ``weather`` (any spec ``--weather`` takes: ``droplets@3``, ``low_light@2``,
    ``fog:0.4,dim:0.3``, a list of effect tables), applied with probability ``p``."""

    def __init__(self, weather: Any = "droplets@3", p: float = 1.0) -> None:
        super().__init__(p=p)
        self.weather = weather
        self._effect = parse_weather(weather)  # a bad spec is refused here, naming it

    def get_params(self) -> dict[str, Any]:
        return {"seed": int(self.random_generator.integers(2**63 - 1))}

    def apply(self, img: np.ndarray, seed: int = 0, **params: Any) -> np.ndarray:
        if not isinstance(img, np.ndarray) or img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
            got = f"{img.dtype} {img.shape}" if isinstance(img, np.ndarray) else type(img).__name__
            raise InputError(f"Weather({self.weather!r}) takes RGB uint8 images of shape (H, W, 3), got {got}")
        return self._effect.start(seed)(img, rng=np.random.default_rng(seed))

    def get_transform_init_args_names(self) -> tuple[str, ...]:
        return ("weather",)
