"""The settings of a detector training run: :class:`TrainConfig` and its named recipes (``RECIPES``).

Example:
    >>> config = TrainConfig.recipe("real", epochs=1)
    >>> config.epochs, config.input_size
    (1, (512, 288))
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from weather_gym.core.errors import InputError, LimitError
from weather_gym.core.limits import check_image_size, check_seed
from weather_gym.lab.training.detector.conenet import DEFAULT_BLOCKS, MAX_BLOCKS, STRIDE, STRIDES

MAX_OBJECTS = 128


@dataclass(frozen=True)
class TrainConfig:
    """Hyper-parameters of ``train_detector`` (defaults = the shipped model's)."""

    input_size: tuple[int, int] = (512, 288)
    epochs: int = 30
    batch_size: int = 16
    lr: float = 3e-3
    weight_decay: float = 5e-4
    warmup_iters: int = 200
    seed: int = 0
    threads: int = 1  # torch threads: 1 is much faster than 2 on a busy 2-core machine (OpenMP spin-waits)
    scale_range: tuple[float, float] = (0.75, 1.35)
    shift: float = 0.12
    flip: float = 0.5
    hue: int = 3  # OpenCV hue units (2 degrees each)
    saturation: float = 0.3
    brightness: float = 0.25
    crop_size: tuple[int, int] | None = (320, 192)  # train on random crops of the input (fully convolutional)
    cache_images: bool = True  # keep decoded frames in memory (about 0.75 MB per 672x376 frame)
    score_threshold: float = 0.3
    repeat_threshold: float | None = 0.5  # repeat-factor sampling of frames with rare classes (LVIS); None = off
    max_steps: int | None = None  # stop after this many optimizer steps (smoke tests)
    distractors: float = 0.0  # probability of pasting unlabelled clutter into a training crop (augment.py)
    camera: float = 0.0  # probability of a random real-camera rendition (exposure, tone, noise, JPEG)
    camera_degrade: bool = False  # the rendition also under-exposes, blurs and adds strong noise (weather-like)
    mix: tuple[float, ...] | None = None  # share of each --data folder in every epoch (None: all frames once)
    epoch_frames: int | None = None  # frames per epoch with ``mix`` (default: as many as without it)
    init: str | None = None  # start from this ConeNet ONNX model (its batch norms stay frozen)
    stride: int = STRIDE  # output grid: 4, or 2 to separate cones whose centres are a few pixels apart
    hidden: bool = False  # add hidden-cone heatmaps (ConeNet(hidden=True)): a peak for a cone behind another
    hidden_boxes: bool = False  # the hidden-cone head regresses the hidden cones' boxes too (needs hidden)
    blocks: tuple[int, int, int, int] = DEFAULT_BLOCKS  # residual blocks at strides 4, 8, 16, 32 (ConeNet)
    stem_blocks: int = 0  # residual blocks at stride 2, after the stem (ConeNet)
    tiny_negatives: bool = False  # a tiny (unscored) cone is ignored in its own class only, a negative for the others
    device: str = "cpu"  # torch device of the net: "cpu", "cuda" or "cuda:N" (the samples are made on the CPU)
    workers: int = 0  # processes that make the training samples (0: in the training process)

    @classmethod
    def recipe(cls, name: str, **overrides) -> TrainConfig:
        """A named recipe (``RECIPES``) with ``overrides``: ``sim`` (the defaults) or ``real``."""
        if name not in RECIPES:
            raise InputError(f"unknown training recipe {name!r}; expected one of {sorted(RECIPES)}")
        return cls(**{**RECIPES[name], **overrides})

    def __post_init__(self) -> None:
        self._check_sampling()
        w, h = self.input_size
        if w % 32 or h % 32:
            raise InputError(f"input_size must be multiples of 32, got {self.input_size}")
        check_image_size((h, w), what=f"input_size {w}x{h} (--input-size)")
        self._check_training_loop()
        if self.crop_size is not None:
            cw, ch = self.crop_size
            if cw % 32 or ch % 32 or cw > w or ch > h:
                raise InputError(f"crop_size must be multiples of 32 within input_size {self.input_size}, got {self.crop_size}")
        if self.epochs < 1 or self.batch_size < 1:
            raise InputError("epochs and batch_size must be >= 1")
        if self.stride not in STRIDES:
            raise InputError(f"stride must be one of {STRIDES}, got {self.stride}")
        if self.workers < 0:
            raise InputError(f"workers must be >= 0, got {self.workers}")
        if self.hidden_boxes and not self.hidden:
            raise InputError("hidden_boxes needs hidden (the boxes are the hidden-cone head's; --hidden-heads)")
        if len(self.blocks) != 4 or any(int(b) != b or b < 0 for b in self.blocks):
            raise InputError(f"blocks must be 4 whole numbers >= 0 (strides 4, 8, 16, 32), got {self.blocks}")
        if max(self.blocks) > MAX_BLOCKS:
            raise LimitError(f"blocks (--blocks) must be at most {MAX_BLOCKS} per stride (default "
                             f"{','.join(map(str, DEFAULT_BLOCKS))}), got {','.join(map(str, self.blocks))}")
        if int(self.stem_blocks) != self.stem_blocks or self.stem_blocks < 0:
            raise InputError(f"stem_blocks must be a whole number >= 0, got {self.stem_blocks}")
        if self.stem_blocks > MAX_BLOCKS:
            raise LimitError(f"stem_blocks (--stem-blocks) must be at most {MAX_BLOCKS}, got {self.stem_blocks}")
        if not (self.device == "cpu" or self.device == "cuda" or
                (self.device.startswith("cuda:") and self.device[5:].isdigit())):
            raise InputError(f"device must be 'cpu', 'cuda' or 'cuda:N', got {self.device!r}")

    def _check_sampling(self) -> None:
        """How the training samples are drawn and augmented: probabilities, ``mix``, epoch size, scale range."""
        for name in ("distractors", "camera"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise InputError(f"{name} must be a probability in [0, 1], got {getattr(self, name)}")
        if self.mix is not None and (not self.mix or any(not (w >= 0) for w in self.mix) or sum(self.mix) <= 0):
            raise InputError(f"mix must be non-negative shares with a positive sum, got {self.mix}")
        if self.epoch_frames is not None and self.epoch_frames < 1:
            raise InputError(f"epoch_frames must be >= 1, got {self.epoch_frames}")
        if not 0 < self.scale_range[0] <= self.scale_range[1]:
            raise InputError(f"scale_range must be 0 < low <= high, got {self.scale_range}")

    def _check_training_loop(self) -> None:
        """The optimiser's learning rate and warm-up, the step limit, torch threads and the seed."""
        if isinstance(self.lr, bool) or not isinstance(self.lr, int | float) or not (0 < self.lr <= 1):
            raise LimitError(f"lr (--lr) must be a learning rate in (0, 1], got {self.lr!r}")
        most = 4 * (os.cpu_count() or 1)
        if isinstance(self.threads, bool) or not isinstance(self.threads, int) or not 1 <= self.threads <= most:
            raise LimitError(f"threads (--threads) must be in 1..{most} (4 per CPU core), got {self.threads!r}")
        check_seed(self.seed, what="seed (--seed)")
        if self.max_steps is not None and (isinstance(self.max_steps, bool) or not isinstance(self.max_steps, int)
                                           or self.max_steps < 1):
            raise InputError(f"max_steps (--max-steps) must be a whole number >= 1, got {self.max_steps!r}")
        if isinstance(self.warmup_iters, bool) or not isinstance(self.warmup_iters, int) or self.warmup_iters < 0:
            raise InputError(f"warmup_iters (--warmup) must be a whole number >= 0, got {self.warmup_iters!r}")


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
