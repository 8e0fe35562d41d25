"""The settings of a detector training run: :class:`TrainConfig` and its named recipes (``RECIPES``).

Example:
    >>> config = TrainConfig.recipe("real", epochs=1)
    >>> config.epochs, config.input_size
    (1, (512, 288))
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import Field

from weather_gym.core.errors import InputError, LimitError
from weather_gym.core.limits import MAX_SEED, check_image_size
from weather_gym.core.schema import (
    ListAsTuple,
    NonNegative,
    NonNegativeInt,
    OneOf,
    Positive,
    PositiveInt,
    Share,
    check_fields,
    option,
)
from weather_gym.lab.training.detector.conenet import DEFAULT_BLOCKS, MAX_BLOCKS, STRIDE, STRIDES

MAX_OBJECTS = 128

#: residual blocks at one stride: a whole number from 0 to MAX_BLOCKS
Blocks = Annotated[int, Field(ge=0, le=MAX_BLOCKS)]


@dataclass(frozen=True)
class TrainConfig:
    """Hyper-parameters of ``train_detector`` (defaults = the shipped model's)."""

    input_size: Annotated[tuple[PositiveInt, PositiveInt], ListAsTuple, option("--input-size")] = (512, 288)
    epochs: Annotated[PositiveInt, option("--epochs")] = 30
    batch_size: Annotated[PositiveInt, option("--batch-size")] = 16
    lr: Annotated[float, Field(gt=0, le=1), option("--lr")] = 3e-3
    weight_decay: float = 5e-4
    warmup_iters: Annotated[NonNegativeInt, option("--warmup")] = 200
    seed: Annotated[int, Field(ge=0, le=MAX_SEED), option("--seed")] = 0
    # torch threads: 1 is much faster than 2 on a busy 2-core machine (OpenMP spin-waits); at most 4 per CPU core
    threads: Annotated[PositiveInt, option("--threads")] = 1
    scale_range: Annotated[tuple[Positive, Positive], ListAsTuple] = (0.75, 1.35)  # low <= high
    shift: float = 0.12
    flip: float = 0.5
    hue: int = 3  # OpenCV hue units (2 degrees each)
    saturation: float = 0.3
    brightness: float = 0.25
    # train on random crops of the input (fully convolutional); multiples of 32 within input_size
    crop_size: Annotated[tuple[PositiveInt, PositiveInt] | None, ListAsTuple, option("--crop-size")] = (320, 192)
    cache_images: bool = True  # keep decoded frames in memory (about 0.75 MB per 672x376 frame)
    score_threshold: Share = 0.3
    repeat_threshold: float | None = 0.5  # repeat-factor sampling of frames with rare classes (LVIS); None = off
    max_steps: Annotated[PositiveInt | None, option("--max-steps")] = None  # stop after this many optimizer steps
    # probability of pasting unlabelled clutter into a training crop (augment.py)
    distractors: Annotated[Share, option("--distractors")] = 0.0
    # probability of a random real-camera rendition (exposure, tone, noise, JPEG)
    camera: Annotated[Share, option("--camera-look")] = 0.0
    camera_degrade: bool = False  # the rendition also under-exposes, blurs and adds strong noise (weather-like)
    # share of each --data folder in every epoch (None: all frames once); their sum > 0
    mix: Annotated[Annotated[tuple[NonNegative, ...], Field(min_length=1)] | None, ListAsTuple, option("--mix")] = None
    epoch_frames: Annotated[PositiveInt | None, option("--epoch-frames")] = None  # frames per epoch with ``mix``
    init: str | None = None  # start from this ConeNet ONNX model (its batch norms stay frozen)
    # output grid: 4, or 2 to separate cones whose centres are a few pixels apart
    stride: Annotated[int, OneOf(STRIDES), option("--stride")] = STRIDE
    hidden: bool = False  # add hidden-cone heatmaps (ConeNet(hidden=True)): a peak for a cone behind another
    hidden_boxes: bool = False  # the hidden-cone head regresses the hidden cones' boxes too (needs hidden)
    # residual blocks at strides 4, 8, 16, 32 (ConeNet)
    blocks: Annotated[tuple[Blocks, Blocks, Blocks, Blocks], ListAsTuple, option("--blocks")] = DEFAULT_BLOCKS
    stem_blocks: Annotated[Blocks, option("--stem-blocks")] = 0  # residual blocks at stride 2, after the stem
    tiny_negatives: bool = False  # a tiny (unscored) cone is ignored in its own class only, a negative for the others
    # torch device of the net: "cpu", "cuda" or "cuda:N" (the samples are made on the CPU)
    device: Annotated[str, Field(pattern=r"^(cpu|cuda|cuda:[0-9]+)$"), option("--device")] = "cpu"
    workers: Annotated[NonNegativeInt, option("--workers")] = 0  # processes that make the training samples (0: in the training process)

    @classmethod
    def recipe(cls, name: str, **overrides) -> TrainConfig:
        """A named recipe (``RECIPES``) with ``overrides``: ``sim`` (the defaults) or ``real``."""
        if name not in RECIPES:
            raise InputError(f"unknown training recipe {name!r}; expected one of {sorted(RECIPES)}")
        return cls(**{**RECIPES[name], **overrides})

    def __post_init__(self) -> None:
        check_fields(self, error=LimitError)  # each field against its annotation; then the relations
        w, h = self.input_size
        if w % 32 or h % 32:
            raise InputError(f"input_size must be multiples of 32, got {self.input_size}")
        check_image_size((h, w), what=f"input_size {w}x{h} (--input-size)")
        if self.crop_size is not None:
            cw, ch = self.crop_size
            if cw % 32 or ch % 32 or cw > w or ch > h:
                raise InputError(f"crop_size must be multiples of 32 within input_size {self.input_size}, got {self.crop_size}")
        if self.hidden_boxes and not self.hidden:
            raise InputError("hidden_boxes needs hidden (the boxes are the hidden-cone head's; --hidden-heads)")
        if self.mix is not None and sum(self.mix) <= 0:
            raise InputError(f"mix must be non-negative shares with a positive sum, got {self.mix}")
        if not self.scale_range[0] <= self.scale_range[1]:
            raise InputError(f"scale_range must be 0 < low <= high, got {self.scale_range}")
        most = 4 * (os.cpu_count() or 1)
        if self.threads > most:
            raise LimitError(f"threads (--threads) must be in 1..{most} (4 per CPU core), got {self.threads!r}")


RECIPES: dict[str, dict[str, Any]] = {
    # the shipped model's first recipe: rendered frames, mild jitter
    "sim": {},
    # for real cameras: near cones big and far ones tiny, the horizon anywhere, clutter that is not a
    # cone, a clear-day camera (exposure to blown-out, white balance, tone, desaturation, mild noise, JPEG)
    "real": {"scale_range": (0.6, 2.2), "shift": 0.25, "hue": 4, "distractors": 0.7, "camera": 0.85},
    # the same plus what the weather effects do (under-exposure, blur, strong noise): robust to the
    # simulator's weather too, so it no longer shows the weather's drop (ablation only)
    "real_robust": {"scale_range": (0.6, 2.2), "shift": 0.25, "hue": 4, "distractors": 0.7, "camera": 0.85,
                    "camera_degrade": True},
}
