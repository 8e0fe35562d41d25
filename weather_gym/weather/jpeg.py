"""JPEG compression artefacts (a camera or a radio link squeezing its bandwidth).

**Meaning of k**: the JPEG quality drops linearly from 100 at k = 0 to ``min_quality`` at k = 1:
``quality = round(100 - k * (100 - min_quality))``. Encoded and decoded with OpenCV (libjpeg-turbo),
in the colour order JPEG expects (decoded straight to RGB), with 4:2:0 chroma subsampling unless
``chroma_subsampling=False``.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.random.default_rng(0).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    >>> out = make("jpeg", k=1.0)(img)
    >>> out.shape, bool((out != img).any())
    ((32, 32, 3), True)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather.base import KnobEffect
from weather_gym.weather.registry import register_effect

__all__ = ["Jpeg"]


@register_effect
@dataclass(frozen=True)
class Jpeg(KnobEffect):
    """Compression; ``k`` lowers the quality from 100 to ``min_quality``. See module doc."""

    name: ClassVar[str] = "jpeg"
    CHAIN_RANK: ClassVar[float] = 110
    NOMINAL_NOUN: ClassVar[str] = "compression artefacts"

    min_quality: float = 5.0
    chroma_subsampling: bool = True

    PARAM_BOUNDS: ClassVar = {"min_quality": (1.0, 95.0)}

    @property
    def quality(self) -> int:
        return int(round(100 - self.k * (100 - self.min_quality)))

    def _params(self) -> list[int]:
        sampling = (cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420 if self.chroma_subsampling
                    else cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444)
        return [cv2.IMWRITE_JPEG_QUALITY, self.quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling]

    def _code(self, bgr: np.ndarray, params: list[int]) -> np.ndarray:
        """Encode a BGR frame, decode straight to RGB."""
        ok, buf = cv2.imencode(".jpg", bgr, params)
        if not ok:  # pragma: no cover - libjpeg does not fail on valid uint8 images
            raise RuntimeError("jpeg: OpenCV could not encode the image")
        return cv2.imdecode(buf, cv2.IMREAD_COLOR_RGB)  # type: ignore[return-value]  # just encoded: never None

    def _render_frame(self, img: np.ndarray, draw: Any, depth: np.ndarray | None,
                      state: dict[str, float]) -> np.ndarray:
        return self._code(cv2.cvtColor(img, cv2.COLOR_RGB2BGR), self._params())

    def _render_batch(self, imgs: np.ndarray, draws: list[Any] | None, depth: np.ndarray | None,
                      states: list[dict[str, float]]) -> np.ndarray:
        params = self._params()
        out = np.empty_like(imgs)
        bgr = np.empty_like(imgs[0])  # one reused (cache-warm) buffer
        for i in range(imgs.shape[0]):
            out[i] = self._code(cv2.cvtColor(imgs[i], cv2.COLOR_RGB2BGR, dst=bgr), params)
        return out
