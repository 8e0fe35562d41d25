"""Label conventions shared by datasets, training and scoring (no heavy imports).

**Too small to count.** A cone whose visible box is shorter than :data:`MIN_INPUT_BOX_PX` (6.1)
pixels *at the detector's input scale* is a *tiny* cone: it is written with ``iscrowd = 1``, it is
neither a positive nor a negative in training, and pycocotools ignores it in scoring (a detection on
it is neither a hit nor a false positive). The rule is stated at the input scale because that is what
the detector sees: the shipped detector letterboxes the default 672x376 camera image into 512x288
(x0.762), where the rule is ``MIN_BOX_HEIGHT_PX = 8`` image pixels (an upright 325 mm cone at about
13.6 m); a 1024x768 frame goes in at x0.375, so there the rule is 16.3 image pixels.
:class:`SmallRule` turns the rule into image pixels for a frame size and a detector input.

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.labels import tiny_mask, MIN_BOX_HEIGHT_PX, SmallRule
    >>> tiny_mask(np.array([[0, 0, 5, 7.0], [0, 0, 5, 8.0]])).tolist(), MIN_BOX_HEIGHT_PX
    ([True, False], 8.0)
    >>> SmallRule.for_image((1024, 768)).describe()
    "box height < 16.3 px (6.1 px at the detector's 512x288 input, letterbox x0.375)"
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import cast

import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError

MIN_BOX_HEIGHT_PX: float = 8.0
"""Boxes shorter than this (pixels of the default 672x376 camera image) are ``iscrowd`` / ignored."""

DEFAULT_INPUT_SIZE: tuple[int, int] = (512, 288)
"""Input (W, H) of the shipped detector."""

MIN_INPUT_BOX_PX: float = MIN_BOX_HEIGHT_PX * 512.0 / 672.0
"""The too-small rule at the detector's input scale: ``MIN_BOX_HEIGHT_PX`` of the default camera
letterboxed into the shipped detector's input (8 x 512/672 = 6.1 px)."""


def input_scale(image_size: tuple[int, int], input_size: tuple[int, int], resize: str = "letterbox") -> float:
    """Vertical scale from image pixels to detector-input pixels (``letterbox``: one scale keeping the
    aspect ratio; ``stretch``: each axis on its own)."""
    (w, h), (iw, ih) = image_size, input_size
    if min(w, h, iw, ih) <= 0:
        raise InputError(f"image size {image_size} and input size {input_size} must be positive")
    if resize == "letterbox":
        return min(iw / w, ih / h)
    if resize == "stretch":
        return ih / h
    raise InputError(f"resize must be 'letterbox' or 'stretch', got {resize!r}")


@dataclass(frozen=True)
class SmallRule:
    """The too-small rule for frames of ``image_size`` fed to a detector with ``input_size``."""

    image_size: tuple[int, int]
    input_size: tuple[int, int] = DEFAULT_INPUT_SIZE
    resize: str = "letterbox"
    min_input_px: float = MIN_INPUT_BOX_PX

    @classmethod
    def for_image(cls, image_size: tuple[int, int], detector: object | None = None) -> SmallRule:
        """The rule at ``detector``'s input (its ``input_size`` and ``resize``; default: the shipped one)."""
        size = tuple(getattr(detector, "input_size", None) or DEFAULT_INPUT_SIZE)
        return cls((int(image_size[0]), int(image_size[1])), (int(size[0]), int(size[1])),
                   str(getattr(detector, "resize", "letterbox") or "letterbox"))

    @property
    def scale(self) -> float:
        return input_scale(self.image_size, self.input_size, self.resize)

    @property
    def min_height_px(self) -> float:
        """The rule in image pixels (boxes shorter than this are too small)."""
        return round(self.min_input_px / self.scale, 6)

    def describe(self) -> str:
        iw, ih = self.input_size
        return (f"box height < {self.min_height_px:.3g} px ({self.min_input_px:.2g} px at the detector's "
                f"{iw}x{ih} input, {self.resize} x{self.scale:.3g})")

    def to_dict(self) -> dict:
        return {"min_height_px": self.min_height_px, "min_input_px": self.min_input_px,
                "input_size": list(self.input_size), "resize": self.resize, "image_size": list(self.image_size),
                "rule": self.describe()}

CATEGORIES: list[dict] = [{"id": i + 1, "name": n, "supercategory": "cone"} for i, n in enumerate(CONE_CLASSES)]
"""COCO categories: id = class id + 1."""


IGNORE = "ignore"
"""Class-map target of classes whose boxes become ignore regions (or, for a detector, are dropped)."""

DEFAULT_CLASSES = "blue_cone=blue,yellow_cone=yellow,orange_cone=orange,large_orange_cone=big_orange,unknown_cone=ignore"
"""The default class map: FSOCO / FSKITTI class names."""


def parse_class_map(spec: str | Mapping[str, str] | None) -> dict[str, str]:
    """``"src=target,..."`` (or a mapping) -> ``{source class: cone class or "ignore"}``; errors name the entry."""
    if spec is None:
        spec = DEFAULT_CLASSES
    items = list(spec.items()) if isinstance(spec, Mapping) else []
    if not isinstance(spec, Mapping):
        for part in str(spec).split(","):
            part = part.strip()
            if not part:
                continue
            src, eq, dst = part.partition("=")
            if not eq or not src.strip() or not dst.strip():
                raise InputError(f"class map entry {part!r}: expected SOURCE=TARGET (e.g. blue_cone=blue, 0=yellow, "
                                 "unknown_cone=ignore)")
            items.append((src.strip(), dst.strip()))
    out: dict[str, str] = {}
    valid = (*CONE_CLASSES, IGNORE)
    for src, dst in items:
        if dst not in valid:
            raise InputError(f"class map entry {src}={dst}: target {dst!r} is not one of {', '.join(valid)}")
        if src in out:
            raise InputError(f"class map: source class {src!r} is mapped twice")
        out[str(src)] = dst
    if not out:
        raise InputError("the class map is empty; give SOURCE=TARGET pairs (e.g. blue_cone=blue)")
    return out



def tiny_mask(boxes_xyxy: np.ndarray, min_height: float = MIN_BOX_HEIGHT_PX) -> np.ndarray:
    """True for boxes (K, 4 xyxy) whose height is below ``min_height`` pixels."""
    b = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    return (b[:, 3] - b[:, 1]) < float(min_height)


HIDDEN_GROW: float = 0.05
"""A cone is *hidden* when its box touches a nearer cone's box grown by this share of that box's width."""


def hidden_mask(boxes_xyxy: np.ndarray, ranges: np.ndarray | None = None, grow: float = HIDDEN_GROW) -> np.ndarray:
    """True for each box (K, 4 xyxy) that touches the box of a nearer cone, widened by ``grow`` of its
    width: the rear cone of a pair, a cone seen behind another. Nearer = smaller ``ranges`` where both
    are finite, else the lower box bottom (on a flat track, the nearer cone stands lower in the image).

    Example:
        >>> import numpy as np
        >>> boxes = np.array([[10, 10, 20, 30], [19, 5, 24, 25], [40, 10, 50, 30.]])
        >>> hidden_mask(boxes, np.array([5.0, 6.0, 5.0])).tolist()
        [False, True, False]
    """
    b = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    r = np.full(len(b), np.nan) if ranges is None else np.asarray(ranges, dtype=np.float64).reshape(-1)
    if len(r) != len(b):
        raise InputError(f"hidden_mask: {len(b)} boxes but {len(r)} ranges")
    g = grow * (b[:, 2] - b[:, 0])
    touch = ((b[None, :, 0] < b[:, None, 2] + g[:, None]) & (b[None, :, 2] > b[:, None, 0] - g[:, None])
             & (b[None, :, 1] < b[:, None, 3]) & (b[None, :, 3] > b[:, None, 1]))  # [i, j]: j touches grown i
    both = np.isfinite(r)[:, None] & np.isfinite(r)[None, :]
    nearer = np.where(both, r[:, None] < r[None, :], b[:, None, 3] > b[None, :, 3])  # [i, j]: i nearer than j
    np.fill_diagonal(touch, False)
    return cast(np.ndarray, (touch & nearer).any(axis=0))


def xyxy_to_xywh(boxes: np.ndarray) -> np.ndarray:
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return np.c_[b[:, :2], b[:, 2:] - b[:, :2]]


def xywh_to_xyxy(boxes: np.ndarray) -> np.ndarray:
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return np.c_[b[:, :2], b[:, :2] + b[:, 2:]]
