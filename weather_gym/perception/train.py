"""Train ``ConeNet`` on rendered COCO datasets and export it to ONNX (needs the ``train`` extra: torch, onnx).

Training is seeded and deterministic in its data order and augmentation (a ``numpy`` Generator per
sample from ``(seed, epoch, index)``, ``torch.manual_seed(seed)``); it checkpoints every epoch and
resumes from ``<out>.ckpt`` after an interruption. Augmentation is geometric (scale, shift,
left-right flip: colours keep their meaning) and photometric (small hue, saturation and brightness
jitter); the ``real`` recipe (:meth:`TrainConfig.recipe`) adds what a real camera and a real track
side do (``weather_gym.perception.augment``: exposure to blown-out, tone, blur, noise, JPEG, wide scale
jitter, unlabelled clutter in cone colours). Several COCO folders can be mixed at given ratios
(``mix``): rendered sets, and imported recordings of a team's own camera (their ignore regions and
ignore masks carry no loss). Training can start from a shipped ONNX model (``init``). The detector is trained on clean frames only - never on weather effects - so that, like the
reference study's detector, its accuracy falls when the weather degrades the image.

Example:
    >>> from weather_gym.perception.train import TrainConfig, train_detector       # doctest: +SKIP
    >>> train_detector(["scratch/data/train"], "model.onnx", TrainConfig(epochs=1))  # doctest: +SKIP
"""

from __future__ import annotations

import io
import json
import math
import os
import pickle
import platform
import time
import warnings
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from tqdm import tqdm

from weather_gym._io import atomic_write, atomic_write_json, check_output, exclusive
from weather_gym.cone_spec import CONE_CLASSES
from weather_gym.datasets.coco import load_coco
from weather_gym.errors import FileFormatError, InputError, LimitError, MissingInputError
from weather_gym.limits import check_image_size, check_seed
from weather_gym.perception.augment import camera_look, paste_distractors
from weather_gym.perception.conenet import (
    DEFAULT_BLOCKS,
    NUM_CLASSES,
    STRIDE,
    STRIDES,
    ConeNet,
    ConeNetExport,
    DWBlock,
    layout,
)
from weather_gym.perception.labels import hidden_mask
from weather_gym.perception.onnx_detector import Detections, load_model_metadata
from weather_gym.perception.preprocess import PAD_VALUE, decode, letterbox, letterbox_params
from weather_gym.perception.scoring import evaluate

__all__ = ["TrainConfig", "train_detector", "export_onnx", "build_targets", "augment", "detection_loss",
           "load_onnx_weights", "RECIPES"]

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
        for name in ("distractors", "camera"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise InputError(f"{name} must be a probability in [0, 1], got {getattr(self, name)}")
        if self.mix is not None and (not self.mix or any(not (w >= 0) for w in self.mix) or sum(self.mix) <= 0):
            raise InputError(f"mix must be non-negative shares with a positive sum, got {self.mix}")
        if self.epoch_frames is not None and self.epoch_frames < 1:
            raise InputError(f"epoch_frames must be >= 1, got {self.epoch_frames}")
        if not 0 < self.scale_range[0] <= self.scale_range[1]:
            raise InputError(f"scale_range must be 0 < low <= high, got {self.scale_range}")
        w, h = self.input_size
        if w % 32 or h % 32:
            raise InputError(f"input_size must be multiples of 32, got {self.input_size}")
        check_image_size((h, w), what=f"input_size {w}x{h} (--input-size)")
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
        if int(self.stem_blocks) != self.stem_blocks or self.stem_blocks < 0:
            raise InputError(f"stem_blocks must be a whole number >= 0, got {self.stem_blocks}")
        if not (self.device == "cpu" or self.device == "cuda" or
                (self.device.startswith("cuda:") and self.device[5:].isdigit())):
            raise InputError(f"device must be 'cpu', 'cuda' or 'cuda:N', got {self.device!r}")


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


# ----------------------------------------------------------------------------------- samples
def augment(image: np.ndarray, boxes: np.ndarray, cfg: TrainConfig, rng: np.random.Generator | None,
            mask: np.ndarray | None = None):
    """Letterbox ``image`` into the input size with a random scale/shift/flip and colour jitter,
    then (with ``cfg.crop_size``) cut a random crop of it; with ``cfg.distractors`` / ``cfg.camera``
    paste unlabelled clutter and apply a random real-camera rendition.

    Returns (image uint8 (h, w, 3), boxes xyxy in its pixels, visible fraction of each box), plus the
    ignore ``mask`` (bool (H, W) of the source image) moved the same way when one is given.
    ``rng=None`` gives the plain letterbox (evaluation).
    """
    ih, iw = image.shape[:2]
    W, H = cfg.input_size
    lb = letterbox_params(iw, ih, cfg.input_size)
    s, tx, ty = lb.scale, float(lb.pad[0]), float(lb.pad[1])
    flip = False
    if rng is not None:
        k = float(rng.uniform(*cfg.scale_range))
        s *= k
        # zoom about the image centre, then shift
        tx = W / 2 - k * (W / 2 - tx) + float(rng.uniform(-cfg.shift, cfg.shift)) * W
        ty = H / 2 - k * (H / 2 - ty) + float(rng.uniform(-cfg.shift, cfg.shift)) * H
        flip = bool(rng.random() < cfg.flip)
    M = np.array([[s, 0, tx], [0, s, ty]], dtype=np.float64)
    if flip:
        M = np.array([[-1, 0, W], [0, 1, 0]], dtype=np.float64) @ np.vstack([M, [0, 0, 1]])
    if rng is not None and cfg.crop_size is not None:
        cw, ch = cfg.crop_size
        M[0, 2] -= float(rng.integers(0, W - cw + 1))
        M[1, 2] -= float(rng.integers(0, H - ch + 1))
        W, H = cw, ch
    out = cv2.warpAffine(image, M, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=(PAD_VALUE,) * 3)
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    xs = b[:, [0, 2]] * M[0, 0] + M[0, 2]
    ys = b[:, [1, 3]] * M[1, 1] + M[1, 2]
    nb = np.c_[xs.min(1), ys.min(1), xs.max(1), ys.max(1)]
    area = np.maximum((nb[:, 2] - nb[:, 0]) * (nb[:, 3] - nb[:, 1]), 1e-9)
    nb[:, [0, 2]] = nb[:, [0, 2]].clip(0, W)
    nb[:, [1, 3]] = nb[:, [1, 3]].clip(0, H)
    visible = (nb[:, 2] - nb[:, 0]).clip(0) * (nb[:, 3] - nb[:, 1]).clip(0) / area
    if rng is not None and (cfg.hue or cfg.saturation or cfg.brightness):
        hsv = cv2.cvtColor(out, cv2.COLOR_RGB2HSV).astype(np.float32)
        hsv[..., 0] = (hsv[..., 0] + float(rng.integers(-cfg.hue, cfg.hue + 1))) % 180
        hsv[..., 1] *= float(rng.uniform(1 - cfg.saturation, 1 + cfg.saturation))
        hsv[..., 2] *= float(rng.uniform(1 - cfg.brightness, 1 + cfg.brightness))
        out = cv2.cvtColor(np.clip(hsv, 0, 255).astype(np.uint8), cv2.COLOR_HSV2RGB)
    if rng is not None and cfg.distractors and rng.random() < cfg.distractors:
        out = paste_distractors(out, nb[visible > 0], rng)
    if rng is not None and cfg.camera and rng.random() < cfg.camera:
        out = camera_look(out, rng, degrade=cfg.camera_degrade)
    if mask is None:
        return out, nb, visible
    moved = cv2.warpAffine(mask.astype(np.uint8), M, (W, H), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                           borderValue=0)
    return out, nb, visible, moved.astype(bool)


def _gaussian(heat: np.ndarray, cx: int, cy: int, sx: float, sy: float) -> None:
    h, w = heat.shape
    rx, ry = int(math.ceil(3 * sx)), int(math.ceil(3 * sy))
    x0, x1 = max(0, cx - rx), min(w, cx + rx + 1)
    y0, y1 = max(0, cy - ry), min(h, cy + ry + 1)
    xs = np.arange(x0, x1) - cx
    ys = np.arange(y0, y1) - cy
    g = np.exp(-(ys[:, None] ** 2) / (2 * sy * sy) - (xs[None, :] ** 2) / (2 * sx * sx))
    np.maximum(heat[y0:y1, x0:x1], g, out=heat[y0:y1, x0:x1])


HIDDEN_BOX_RADIUS = 2
"""A hidden cone's box is regressed from every cell at most this many cells from its centre's cell."""


def build_targets(boxes: np.ndarray, classes: np.ndarray, ignore: np.ndarray, input_size: tuple[int, int],
                  stride: int = STRIDE, hidden: np.ndarray | None = None, hidden_boxes: bool = False, *,
                  own_class: np.ndarray | None = None):
    """CenterNet targets at ``stride``: heat (C, h, w), ignore map (C, h, w: 1 where a class's heatmap
    carries no negative loss), and per-object
    index / log-size / offset / mask arrays of length ``MAX_OBJECTS``. With ``hidden`` (bool per box,
    ``labels.hidden_mask``) heat has ``2C`` channels: the last ``C`` hold the hidden cones only (they
    stay in the first ``C`` too). With ``hidden_boxes`` two dense maps follow: the hidden cones' box
    targets (4, h, w: log size, and their centre's offset from the cell in cells) in the cells within
    ``HIDDEN_BOX_RADIUS`` of their centre (the nearest centre where two overlap), and its mask (h, w).
    An ignored box (``ignore``) is ignored in every class's heatmap, or, where ``own_class`` (bool per box)
    is set, in its own class's only: the other classes learn that it is not one of theirs (a tiny far
    yellow cone is not a big orange one)."""
    W, H = input_size
    ow, oh = W // stride, H // stride
    heat = np.zeros((NUM_CLASSES * (1 if hidden is None else 2), oh, ow), np.float32)
    ign = np.zeros((NUM_CLASSES, oh, ow), np.float32)
    own = np.zeros(len(boxes), bool) if own_class is None else np.asarray(own_class, bool)
    ind = np.zeros(MAX_OBJECTS, np.int64)
    size = np.zeros((MAX_OBJECTS, 2), np.float32)
    off = np.zeros((MAX_OBJECTS, 2), np.float32)
    mask = np.zeros(MAX_OBJECTS, np.float32)
    k = 0
    hid = np.zeros(len(boxes), bool) if hidden is None else np.asarray(hidden, bool)
    if hidden_boxes and hidden is None:
        raise InputError("hidden-cone box targets need the hidden mask (labels.hidden_mask)")
    hreg = np.zeros((4, oh, ow), np.float32) if hidden_boxes else None
    hmask = np.zeros((oh, ow), np.float32) if hidden_boxes else None
    hdist = np.full((oh, ow), np.inf) if hidden_boxes else None
    for b, c, ig, hd, oc in zip(boxes, classes, ignore, hid, own, strict=True):
        bw, bh = b[2] - b[0], b[3] - b[1]
        if bw <= 0 or bh <= 0:
            continue
        if ig:
            x0, y0 = int(b[0] // stride), int(b[1] // stride)
            x1, y1 = int(math.ceil(b[2] / stride)), int(math.ceil(b[3] / stride))
            ign[int(c) if oc else slice(None), max(0, y0 - 1) : min(oh, y1 + 1), max(0, x0 - 1) : min(ow, x1 + 1)] = 1.0
            continue
        if k >= MAX_OBJECTS:
            continue
        cx, cy = (b[0] + b[2]) / 2 / stride, (b[1] + b[3]) / 2 / stride
        ix, iy = min(int(cx), ow - 1), min(int(cy), oh - 1)
        sx = max(0.6, 0.15 * bw / stride)
        sy = max(0.6, 0.15 * bh / stride)
        for ch in (int(c), int(c) + NUM_CLASSES) if hd else (int(c),):
            _gaussian(heat[ch], ix, iy, sx, sy)
            heat[ch, iy, ix] = 1.0
        ind[k] = iy * ow + ix
        size[k] = (math.log(max(bw, 1.0) / stride), math.log(max(bh, 1.0) / stride))
        off[k] = (cx - ix, cy - iy)
        mask[k] = 1.0
        k += 1
        if hd and hreg is not None:
            r = HIDDEN_BOX_RADIUS
            x0, x1, y0, y1 = max(0, ix - r), min(ow, ix + r + 1), max(0, iy - r), min(oh, iy + r + 1)
            gx, gy = np.meshgrid(np.arange(x0, x1), np.arange(y0, y1))
            d = (gx + 0.5 - cx) ** 2 + (gy + 0.5 - cy) ** 2
            near = d < hdist[y0:y1, x0:x1]
            hdist[y0:y1, x0:x1][near] = d[near]
            for ch, v in enumerate((size[k - 1, 0], size[k - 1, 1], cx - gx, cy - gy)):
                hreg[ch, y0:y1, x0:x1][near] = np.broadcast_to(v, d.shape)[near]
            hmask[y0:y1, x0:x1][near] = 1.0
    if hreg is not None:
        return heat, ign, ind, size, off, mask, hreg, hmask
    return heat, ign, ind, size, off, mask


class _Frames(torch.utils.data.Dataset):
    """(dataset, index) pairs of one or more ``CocoDataset``; augmentation seeded per (epoch, item)."""

    def __init__(self, datasets: list, cfg: TrainConfig, train: bool) -> None:
        self.items = [(d, i) for d in datasets for i in range(len(d))]
        self.source = np.array([k for k, d in enumerate(datasets) for _ in range(len(d))], np.int64)
        if cfg.mix is not None and len(cfg.mix) != len(datasets):
            raise InputError(f"mix gives {len(cfg.mix)} shares for {len(datasets)} data folders: give one per folder")
        if cfg.mix is not None:
            for k, (d, w) in enumerate(zip(datasets, cfg.mix, strict=True)):
                if w > 0 and len(d) == 0:
                    raise InputError(f"data folder {k + 1} ({d.root}) has no images but a mix share of {w}")
        self.cfg = cfg
        self.train = train
        self._cache: dict[int, np.ndarray] = {}
        self.repeat = np.ones(len(self.items))
        if train and cfg.repeat_threshold:
            # repeat factor sampling (Gupta et al., LVIS 2019): a frame is seen max_c sqrt(t / f_c) times
            # per epoch (at least once), f_c = fraction of frames showing a scorable cone of class c
            present = np.zeros((len(self.items), NUM_CLASSES), bool)
            for k, (d, i) in enumerate(self.items):
                g = d.gt(i)
                present[k, g["classes"][g["iscrowd"] == 0]] = True
            freq = np.maximum(present.mean(axis=0), 1e-9)
            per_class = np.maximum(1.0, np.sqrt(cfg.repeat_threshold / freq))
            self.repeat = np.where(present, per_class[None, :], 1.0).max(axis=1)

    def epoch_size(self) -> int:
        """Frames per epoch: the repeat-factor sum, or ``cfg.epoch_frames`` when mixing."""
        if self.cfg.mix is not None and self.cfg.epoch_frames is not None:
            return self.cfg.epoch_frames
        return int(round(float(self.repeat.sum())))

    def epoch_order(self, epoch: int) -> np.ndarray:
        """Frame indices of one epoch, shuffled (seeded). Without ``mix``: every frame, repeat factors
        rounded stochastically. With ``mix``: each folder's share of ``epoch_size()`` frames, drawn
        from that folder in proportion to the repeat factors (without replacement while it has enough)."""
        rng = np.random.default_rng([self.cfg.seed, epoch, 7])
        if self.cfg.mix is None:
            counts = np.floor(self.repeat + rng.random(len(self.repeat))).astype(np.int64)
            return rng.permutation(np.repeat(np.arange(len(self.repeat)), counts))
        shares = np.asarray(self.cfg.mix, float) / float(sum(self.cfg.mix))
        n = self.epoch_size()
        picks = []
        for k, share in enumerate(shares):
            idx = np.flatnonzero(self.source == k)
            want = int(round(share * n))
            if want == 0 or len(idx) == 0:
                continue
            p = self.repeat[idx] / self.repeat[idx].sum()
            picks.append(rng.choice(idx, size=want, replace=want > len(idx), p=p))
        return rng.permutation(np.concatenate(picks)) if picks else np.zeros(0, np.int64)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, key: int | tuple[int, int]):
        """Sample ``key``: an ``(epoch, index)`` pair, or a frame index (epoch 0's augmentation)."""
        epoch, idx = key if isinstance(key, tuple) else (0, key)
        ds, i = self.items[idx]
        image = self._cache.get(idx)
        if image is None:
            image = ds.image(i)
            if self.cfg.cache_images and torch.utils.data.get_worker_info() is None:  # workers decode each time
                self._cache[idx] = image
        gt = ds.gt(i)
        rng = np.random.default_rng([self.cfg.seed, epoch, idx]) if self.train else None
        mask = gt.get("ignore_mask")
        if mask is None:
            img, boxes, visible = augment(image, gt["boxes"], self.cfg, rng)
        else:
            img, boxes, visible, mask = augment(image, gt["boxes"], self.cfg, rng, mask=mask)
        # crowd (tiny) cones, ignore regions of imported sets and cones mostly pushed out of the frame
        # are ignored, not negatives
        every_class = visible < 0.5
        if "ignore" in gt:
            every_class = every_class | gt["ignore"] | gt["any_class"]
        tiny = (gt["iscrowd"] > 0) & ~every_class
        ignore = tiny | every_class
        # with tiny_negatives a tiny cone is ignored in its own class only (a negative for the others)
        own_class = tiny if self.cfg.tiny_negatives else None
        hidden = hidden_mask(boxes, gt.get("ranges")) if self.cfg.hidden else None
        targets = build_targets(boxes, gt["classes"], ignore, (img.shape[1], img.shape[0]), self.cfg.stride, hidden,
                                self.cfg.hidden_boxes, own_class=own_class)
        if mask is not None:  # the ignore mask (e.g. the ego vehicle): no negative loss under it
            h, w = targets[1].shape[-2:]
            cover = cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
            np.maximum(targets[1], (cover > 0.5).astype(np.float32)[None], out=targets[1])
        x = torch.from_numpy(np.ascontiguousarray(img.transpose(2, 0, 1))).float() / 255.0
        return (x, *[torch.from_numpy(t) for t in targets])


# ----------------------------------------------------------------------------------- loss
def detection_loss(raw: torch.Tensor, heat, ign, ind, size, off, mask, hreg=None, hmask=None
                   ) -> tuple[torch.Tensor, dict[str, float]]:
    """Penalty-reduced focal loss on the heatmaps (ignored cells carry no negative loss) + L1 on
    log-size and offset at object centres. A hidden-cone net (raw ``2C+4`` channels, heat ``2C``) gets
    the same focal loss on its hidden-cone heatmaps, reported as ``hidden``; one with hidden-cone boxes
    (raw ``2C+8``) an L1 on their log size and offset in the cells of ``hmask`` (``hreg`` the targets of
    ``build_targets(..., hidden_boxes=True)``), averaged over those cells, reported as ``hidden_box``."""
    c = NUM_CLASSES
    n = mask.sum().clamp(min=1.0)

    def focal_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        pred = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
        pos = target.eq(1.0).float()
        neg_w = torch.pow(1 - target, 4) * (1 - (ign[:, None] if ign.dim() == 3 else ign)) * (1 - pos)
        pos_loss = (torch.log(pred) * torch.pow(1 - pred, 2) * pos).sum()
        neg_loss = (torch.log(1 - pred) * torch.pow(pred, 2) * neg_w).sum()
        return -(pos_loss + neg_loss) / n

    focal = focal_loss(raw[:, :c], heat[:, :c])
    extra: dict[str, float] = {}
    if raw.shape[1] in (2 * c + 4, 2 * c + 8):
        if heat.shape[1] != 2 * c:
            raise InputError(f"a hidden-cone net needs {2 * c} heat targets, got {heat.shape[1]}")
        hidden = focal_loss(raw[:, c + 4 : 2 * c + 4], heat[:, c:])
        focal = focal + hidden
        extra["hidden"] = hidden.item()
    if raw.shape[1] == 2 * c + 8:
        if hreg is None or hmask is None:
            raise InputError("a net with hidden-cone boxes needs their targets (build_targets(..., hidden_boxes=True))")
        hm = hmask[:, None]
        hidden_box = (torch.abs(raw[:, 2 * c + 4 :] - hreg) * hm).sum() / hmask.sum().clamp(min=1.0)
        extra["hidden_box"] = hidden_box.item()
    else:
        hidden_box = 0.0
    b, _, h, w = raw.shape
    flat = raw[:, c : c + 4].reshape(b, 4, h * w)
    g = torch.gather(flat, 2, ind[:, None, :].expand(b, 4, ind.shape[1]))  # (B, 4, M)
    m = mask[:, None, :]
    size_l = (torch.abs(g[:, :2] - size.transpose(1, 2)) * m).sum() / n
    off_l = (torch.abs(torch.sigmoid(g[:, 2:]) - off.transpose(1, 2)) * m).sum() / n
    total = focal + size_l + off_l + hidden_box
    return total, {"focal": focal.item(), "size": size_l.item(), "offset": off_l.item(), **extra}


# ----------------------------------------------------------------------------------- export
def _hidden_text(net: ConeNet) -> str:
    return ", hidden-cone heads and boxes" if net.hidden_boxes else ", hidden-cone heads" if net.hidden else ""


def count_flops(net: ConeNet, input_size: tuple[int, int]) -> int:
    """FLOPs (2 x multiply-adds) of one forward pass at ``input_size``, counted by torch."""
    from torch.utils.flop_counter import FlopCounterMode

    w, h = input_size
    with torch.no_grad(), FlopCounterMode(display=False) as fc:
        ConeNetExport(net).eval()(torch.zeros(1, 3, h, w))
    return int(fc.get_total_flops())


def export_onnx(net: ConeNet, path: str | os.PathLike, input_size: tuple[int, int], meta: dict | None = None, *,
                overwrite: bool = False) -> Path:
    """Export ``net`` (with sigmoid + peak filter) to ONNX with a dynamic batch, plus its JSON sidecar.

    Both files are written safely (``weather_gym._io``); existing ones only with ``overwrite``.
    """
    import onnx

    path = Path(path)
    sidecar_path = path.with_suffix(".json")
    for p in (path, sidecar_path):
        check_output(p, overwrite=overwrite, what="model file")
    w, h = input_size
    model = ConeNetExport(net.eval()).eval()
    buf = io.BytesIO()  # made in memory, then written by the safe writer: a full disk is an OutputPathError
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(model, torch.zeros(1, 3, h, w), buf, input_names=["images"],
                          output_names=["output"], dynamic_axes={"images": {0: "batch"}, "output": {0: "batch"}},
                          opset_version=17, dynamo=False)
    onnx.checker.check_model(onnx.load_from_string(buf.getvalue()))
    atomic_write(path, buf.getvalue(), overwrite=overwrite)
    sidecar = {
        "format": "weather-gym cone detector v1",
        "architecture": f"ConeNet (CenterNet-style, stride {net.stride}{_hidden_text(net)})",
        "input_size": [w, h],
        "input": "images: float32 (batch, 3, H, W) RGB 0..255, letterboxed (pad 114, centred)",
        "output": f"output: (batch, C+4, H/{net.stride}, W/{net.stride}) = peak-filtered class scores, box w/h (input px), centre offset",
        "classes": list(CONE_CLASSES),
        "stride": net.stride,
        "layout": net.arch,
        "params": int(sum(p.numel() for p in net.parameters())),
        "flops": count_flops(net, input_size),
        **(meta or {}),
    }
    atomic_write_json(sidecar_path, sidecar, indent=2, overwrite=overwrite)
    return path


# ----------------------------------------------------------------------------------- start weights
def load_onnx_weights(net: ConeNet, path: str | os.PathLike) -> ConeNet:
    """Load the weights of a ConeNet ONNX export (``export_onnx``) into ``net`` and return it.

    The export folds each batch norm into its convolution, so the convolutions get the folded weights
    and each batch norm becomes the identity with the folded bias (mean 0, variance 1 - eps, scale 1);
    train such a net with its batch norms in eval mode (``train_detector`` does with ``init``).
    Convolutions are matched in execution order and checked by shape. A stride-2 ``net`` can start
    from a stride-4 model: the shared layers get its weights, the finer pyramid level starts as the
    identity (``ConeNet``) and the size outputs are rescaled to the finer grid. A hidden-cone ``net``
    can start from a model without that head: its head starts as a copy of the main head, its
    heatmaps from the prior; a net with hidden-cone boxes can start from one with the hidden-cone
    heatmaps alone (the box outputs start from their prior). A net with more residual blocks (``blocks``,
    ``stem_blocks``; the file's layout is its sidecar's ``layout``) starts as the file's model, each added
    block as the identity.
    """
    import onnx
    from onnx import numpy_helper

    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"start model {path} does not exist")
    file_layout = _file_layout(path)
    if file_layout != net.arch:  # a deeper net: load the file into its own layout, then grow (one read)
        return _grow(net, file_layout, path)
    try:
        model = onnx.load(str(path))
    except Exception as exc:  # noqa: BLE001 - onnx raises several types for a bad file
        raise FileFormatError(f"{path} is not an ONNX model ({type(exc).__name__})") from None
    inits = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    for node in model.graph.node:  # the exporter shares equal weights through Identity nodes
        if node.op_type == "Identity" and node.input[0] in inits:
            inits[node.output[0]] = inits[node.input[0]]
    onnx_convs = [n for n in model.graph.node if n.op_type == "Conv"]
    order: list[torch.nn.Conv2d] = []
    hooks = [m.register_forward_hook(lambda mod, *_: order.append(mod)) for m in net.modules()
             if isinstance(m, torch.nn.Conv2d)]
    w, h = 128, 64
    with torch.no_grad():
        net.eval()(torch.zeros(1, 3, h, w))
    for hk in hooks:
        hk.remove()
    if net.hidden and len(order) == len(onnx_convs) + 3:  # no hidden-cone head (2 convs + output) in the file
        plain = load_onnx_weights(ConeNet(net.num_classes, stride=net.stride), path)
        missing, unexpected = net.load_state_dict(plain.state_dict(), strict=False)
        if unexpected or any(not k.startswith(("head_hidden.", "out_hidden.")) for k in missing):
            raise FileFormatError(f"{path}: not a ConeNet export that a hidden-cone ConeNet can start from")
        net.head_hidden.load_state_dict(plain.head.state_dict())
        return net
    last = inits.get(onnx_convs[-1].input[1]) if onnx_convs else None
    if (net.hidden_boxes and len(order) == len(onnx_convs) and last is not None
            and last.shape[0] == net.num_classes):  # hidden-cone heatmaps in the file, but not their boxes
        heads = load_onnx_weights(ConeNet(net.num_classes, stride=net.stride, hidden=True), path)
        state = {k: v for k, v in heads.state_dict().items() if not k.startswith("out_hidden.")}
        missing, unexpected = net.load_state_dict(state, strict=False)
        if unexpected or any(not k.startswith("out_hidden.") for k in missing):
            raise FileFormatError(f"{path}: not a ConeNet export that a ConeNet with hidden-cone boxes can start from")
        with torch.no_grad():  # the heatmaps as they were; the boxes start from the prior (size 1 cell, mid-cell)
            net.out_hidden.weight[: net.num_classes] = heads.out_hidden.weight
            net.out_hidden.bias[: net.num_classes] = heads.out_hidden.bias
        return net
    if len(order) != len(onnx_convs) and net.stride == 2:
        coarse = load_onnx_weights(ConeNet(net.num_classes, stride=4), path)
        missing, unexpected = net.load_state_dict(coarse.state_dict(), strict=False)
        if unexpected or any(not k.startswith(("lateral_fine.", "smooth_fine.")) for k in missing):
            raise FileFormatError(f"{path}: not a ConeNet export that a stride-2 ConeNet can start from")
        for m in [*net.lateral_fine.modules(), *net.smooth_fine.modules()]:  # the fresh level's batch norms:
            if isinstance(m, torch.nn.BatchNorm2d):  # identity, as the loaded ones
                m.running_mean.zero_()
                m.running_var.fill_(1.0 - m.eps)
        with torch.no_grad():  # log(w / 4) -> log(w / 2)
            net.out.bias[net.num_classes : net.num_classes + 2] += math.log(2.0)
        return net
    if len(order) != len(onnx_convs):
        raise FileFormatError(f"{path}: {len(onnx_convs)} convolutions, but ConeNet has {len(order)}: not a ConeNet export")
    bn_after = {}
    for mod in net.modules():
        if isinstance(mod, torch.nn.Sequential):
            kids = list(mod)
            for a, b in zip(kids, kids[1:], strict=False):
                if isinstance(a, torch.nn.Conv2d) and isinstance(b, torch.nn.BatchNorm2d):
                    bn_after[a] = b
    with torch.no_grad():
        for conv, node in zip(order, onnx_convs, strict=True):
            weight = inits.get(node.input[1])
            bias = inits.get(node.input[2]) if len(node.input) > 2 else None
            if weight is None or tuple(weight.shape) != tuple(conv.weight.shape):
                raise FileFormatError(f"{path}: convolution {node.name} does not match ConeNet's {tuple(conv.weight.shape)}")
            conv.weight.copy_(torch.from_numpy(weight.copy()))
            bn = bn_after.get(conv)
            if bn is not None:
                bn.running_mean.zero_()
                bn.running_var.fill_(1.0 - bn.eps)
                bn.weight.fill_(1.0)
                bn.bias.copy_(torch.from_numpy(bias.copy()) if bias is not None else torch.zeros_like(bn.bias))
            elif conv.bias is not None and bias is not None:
                conv.bias.copy_(torch.from_numpy(bias.copy()))
    return net


def _file_layout(path: Path) -> dict[str, Any]:
    """The ConeNet layout of a model file, from its sidecar's ``layout`` (files without one: the default)."""
    default = layout()
    found = load_model_metadata(path).get("layout", default)
    if not isinstance(found, dict) or set(found) != set(default):
        raise FileFormatError(f"model sidecar {path.with_suffix('.json')}: 'layout' must have the keys "
                              f"{sorted(default)}, got {found!r}")
    return found


def _grow(net: ConeNet, file_layout: dict[str, Any], path: Path) -> ConeNet:
    """Load a model file with fewer residual blocks into ``net`` (deeper, else the same): the shared layers
    get its weights, each added block starts as the identity (its last batch norm's scale and shift at 0), so
    ``net`` starts as the file's model and fine-tuning gives the new blocks their part."""
    same = file_layout["widths"] == list(net.widths) and file_layout["neck"] == net.neck
    deeper = all(a >= b for a, b in zip(net.blocks, file_layout["blocks"], strict=True)) and \
        net.stem_blocks >= file_layout["stem_blocks"]
    if not (same and deeper):
        raise FileFormatError(f"{path}: its ConeNet layout {file_layout} cannot start a net with {net.arch} (only added "
                              "residual blocks, same widths and neck)")
    base = ConeNet(net.num_classes, widths=tuple(file_layout["widths"]), blocks=tuple(file_layout["blocks"]),
                   neck=file_layout["neck"], stem_blocks=file_layout["stem_blocks"], stride=net.stride, hidden=net.hidden,
                   hidden_boxes=net.hidden_boxes)
    load_onnx_weights(base, path)
    missing, unexpected = net.load_state_dict(base.state_dict(), strict=False)
    added = {f"stages.{i}.{j}" for i, (a, b) in enumerate(zip(net.blocks, file_layout["blocks"], strict=True))
             for j in range(b + 1, a + 1)} | {f"stem_refine.{j}" for j in range(file_layout["stem_blocks"], net.stem_blocks)}
    if unexpected or any(not k.startswith(tuple(f"{a}." for a in added)) for k in missing):
        raise FileFormatError(f"{path}: not a ConeNet export that a net with {net.arch} can start from")
    with torch.no_grad():
        for name, mod in net.named_modules():
            if name in added and isinstance(mod, DWBlock):
                mod.pw[1].weight.zero_()
                mod.pw[1].bias.zero_()
    return net


def _stack(batch: list[tuple[torch.Tensor, ...]]) -> tuple[torch.Tensor, ...]:
    """One training batch: the samples' tensors stacked field by field."""
    return tuple(torch.stack(t) for t in zip(*batch, strict=True))


class _EpochBatches:
    """The batch sampler of a training run: the current epoch's batches of ``(epoch, frame)`` keys."""

    def __init__(self) -> None:
        self.batches: list[list[tuple[int, int]]] = []

    def __iter__(self):
        return iter(self.batches)

    def __len__(self) -> int:
        return len(self.batches)


def _one_thread(_worker: int) -> None:
    """A sample worker's OpenCV runs on one thread (the workers are the parallelism)."""
    cv2.setNumThreads(1)


def _device(name: str) -> torch.device:
    """``TrainConfig.device`` as a torch device; a clear error where CUDA is asked for and absent."""
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"device {name!r}: this torch ({torch.__version__}) sees no CUDA GPU; use --device cpu")
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise InputError(f"device {name!r}: only {torch.cuda.device_count()} CUDA GPU(s) are visible")
    return device


def _hardware(cfg: TrainConfig, device: torch.device) -> str:
    """Where the net was trained, for the sidecar."""
    cpu = f"{platform.processor() or platform.machine()}, {cfg.threads} torch threads, {cfg.workers} sample workers"
    if device.type == "cuda":
        return f"{torch.cuda.get_device_name(device)} (CUDA); {cpu}"
    return f"{cpu}, CPU"


def _freeze_bn(net: ConeNet) -> None:
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.eval()


# ----------------------------------------------------------------------------------- training
def _eval_map(net: ConeNet, val, cfg: TrainConfig, max_images: int = 200) -> float:
    """mAP@0.5 of the torch model on (up to ``max_images`` frames of) ``val``, via the runtime decoder."""

    model = ConeNetExport(net).eval()
    n = min(len(val), max_images)
    dets, gts = [], []
    with torch.no_grad():
        for start in range(0, n, 16):
            idx = range(start, min(n, start + 16))
            ims = [val.image(i) for i in idx]
            boxed = [letterbox(im, cfg.input_size) for im in ims]
            x = torch.from_numpy(np.stack([b[0].transpose(2, 0, 1) for b in boxed])).float()
            out = model(x.to(next(net.parameters()).device)).cpu().numpy()
            for (boxes, scores, classes), (_, lb) in zip(decode(out, NUM_CLASSES, net.stride, 0.05), boxed, strict=True):
                dets.append(Detections(lb.to_original(boxes).astype(np.float32), scores, classes))
            gts += [val.gt(i) for i in idx]
    return evaluate(gts, dets).map50


def _same_run(ckpt: Path, state: dict, cfg: TrainConfig, data: list) -> None:
    """Refuse to resume ``ckpt`` with other settings or data (InputError naming what differs)."""
    before = state.get("config") if isinstance(state.get("config"), dict) else {}
    now = asdict(cfg)
    diff = [k for k in now if before.get(k) != now[k]] + [k for k in before if k not in now]
    if state.get("data") != [str(d) for d in data]:
        diff.append("data")
    if diff:
        shown = "; ".join(f"{k}: {before.get(k, state.get(k))!r} there, "
                          f"{now.get(k, [str(d) for d in data] if k == 'data' else None)!r} now" for k in diff[:4])
        raise InputError(f"checkpoint {ckpt} was made with other settings ({', '.join(diff)}): {shown}. Resume with "
                         "the same settings, or pass --no-resume (or delete it) to start again")


def train_detector(
    data: list[str | os.PathLike],
    out: str | os.PathLike,
    cfg: TrainConfig = TrainConfig(),
    *,
    val: str | os.PathLike | None = None,
    resume: bool = True,
    overwrite: bool = False,
    progress: bool = True,
    log=print,
) -> dict[str, Any]:
    """Train on the COCO folders ``data`` and write ``out`` (ONNX) + its sidecar; returns a summary.

    A checkpoint ``<out>.ckpt`` is written after every epoch; when it exists (and ``resume``),
    training continues from it. It is removed once the ONNX file is written. An existing ``out``
    (or its sidecar) is refused before training unless ``overwrite``. With ``cfg.workers`` the sample
    workers are spawned processes (a fork of a process with threads can deadlock), so a script that
    calls this needs the usual ``if __name__ == "__main__":`` guard.
    """


    if not data:
        raise InputError("no training data given")
    out = Path(out)
    check_output(out, overwrite=overwrite, suffixes=(".onnx",), what="model file")
    check_output(out.with_suffix(".json"), overwrite=overwrite, what="model sidecar")
    with exclusive(out, message=f"another training run is writing {out}; wait for it or choose another --out"):
        return _train_locked(data, out, cfg, val=val, resume=resume, overwrite=overwrite, progress=progress, log=log)


def _train_locked(data: list, out: Path, cfg: TrainConfig, *, val, resume: bool, overwrite: bool, progress: bool,
                  log) -> dict[str, Any]:
    """:func:`train_detector` once its outputs are checked and locked for this run."""
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    train_sets = [load_coco(d) for d in data]
    val_set = load_coco(val) if val is not None else None
    frames = _Frames(train_sets, cfg, train=True)
    if len(frames) == 0:
        raise InputError(f"the training data {', '.join(map(str, data))} has no images")
    net = ConeNet(stride=cfg.stride, hidden=cfg.hidden, hidden_boxes=cfg.hidden_boxes, blocks=cfg.blocks,
                  stem_blocks=cfg.stem_blocks)
    if cfg.init is not None:
        load_onnx_weights(net, cfg.init)
    device = _device(cfg.device)
    net = net.to(device, memory_format=torch.channels_last)  # much faster convolutions on CPU
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps_per_epoch = math.ceil(frames.epoch_size() / cfg.batch_size)
    total_steps = steps_per_epoch * cfg.epochs if cfg.max_steps is None else min(cfg.max_steps, steps_per_epoch * cfg.epochs)

    def lr_at(step: int) -> float:
        if step < cfg.warmup_iters:
            return cfg.lr * (step + 1) / cfg.warmup_iters
        t = (step - cfg.warmup_iters) / max(1, total_steps - cfg.warmup_iters)
        return cfg.lr * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(1.0, t))))

    ckpt = out.with_name(out.name + ".ckpt")
    start_epoch, step, history, elapsed = 0, 0, [], 0.0
    if resume and ckpt.is_file():
        try:  # tensors and plain values only: a checkpoint cannot run code when it is loaded
            state = torch.load(ckpt, map_location="cpu", weights_only=True)
        except (pickle.UnpicklingError, RuntimeError, EOFError, OSError, ValueError, zipfile.BadZipFile) as exc:
            raise FileFormatError(f"checkpoint {ckpt} cannot be read ({type(exc).__name__}); delete it to start "
                                  "again") from None
        if not isinstance(state, dict):
            raise FileFormatError(f"checkpoint {ckpt} is not a training checkpoint; delete it to start again")
        _same_run(ckpt, state, cfg, data)
        net.load_state_dict(state["model"])
        opt.load_state_dict(state["optim"])
        start_epoch, step, history, elapsed = state["epoch"], state["step"], state["history"], state["elapsed"]
        log(f"resuming from {ckpt} at epoch {start_epoch}")
    t_start = time.perf_counter() - elapsed
    batches = _EpochBatches()
    # sample workers are spawned, not forked (a fork of a process with threads can deadlock), and live for
    # the whole run; each batch names its epoch, so a worker makes any epoch's samples
    loader = torch.utils.data.DataLoader(frames, batch_sampler=batches, num_workers=cfg.workers, collate_fn=_stack,
                                         worker_init_fn=_one_thread, pin_memory=device.type == "cuda",
                                         multiprocessing_context="spawn" if cfg.workers else None,
                                         persistent_workers=cfg.workers > 0)
    for epoch in range(start_epoch, cfg.epochs):
        if step >= total_steps:
            break
        order = frames.epoch_order(epoch)
        net.train()
        if cfg.init is not None:
            _freeze_bn(net)
        sums: dict[str, float] = {}
        nb = 0
        batches.batches = [[(epoch, int(i)) for i in order[s : s + cfg.batch_size]]
                           for s in range(0, len(order), cfg.batch_size)]
        bar = tqdm(loader, total=len(batches), desc=f"epoch {epoch + 1}/{cfg.epochs}", disable=not progress,
                   leave=False)
        for batch in bar:
            x, *targets = (t.to(device, non_blocking=True) for t in batch)
            x = x.contiguous(memory_format=torch.channels_last)
            for g in opt.param_groups:
                g["lr"] = lr_at(step)
            loss, parts = detection_loss(net(x), *targets)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 10.0)
            opt.step()
            step += 1
            nb += 1
            for k, v in {"loss": loss.item(), **parts}.items():
                sums[k] = sums.get(k, 0.0) + v
            bar.set_postfix(loss=f"{sums['loss'] / nb:.3f}")
            if step >= total_steps:
                break
        entry = {"epoch": epoch + 1, "step": step, **{k: v / max(nb, 1) for k, v in sums.items()},
                 "elapsed_s": time.perf_counter() - t_start}
        if val_set is not None and ((epoch + 1) % 5 == 0 or epoch + 1 == cfg.epochs or step >= total_steps):
            entry["val_map50"] = _eval_map(net, val_set, cfg)
        history.append(entry)
        buf = io.BytesIO()  # torch's own file writer reports a full disk as a RuntimeError: write it ourselves
        torch.save({"model": net.state_dict(), "optim": opt.state_dict(), "epoch": epoch + 1, "step": step,
                    "history": history, "elapsed": time.perf_counter() - t_start, "config": asdict(cfg),
                    "data": [str(d) for d in data]}, buf)
        atomic_write(ckpt, buf.getvalue(), overwrite=True)  # the run's own checkpoint, replaced every epoch
        log(json.dumps(entry))
    train_time = time.perf_counter() - t_start
    meta = {
        "score_threshold": cfg.score_threshold,
        "training": {
            "data": [str(d) for d in data],
            "tracks": sorted({str(im.get("track")) for d in train_sets for im in d.images}),
            "frames": len(frames),
            "frames_per_data": [len(d) for d in train_sets],
            "val": str(val) if val is not None else None,
            "config": asdict(cfg),
            "steps": step,
            "train_time_s": round(train_time, 1),
            "hardware": _hardware(cfg, device),
            "torch": torch.__version__,
            "history": history,
        },
    }
    export_onnx(net.to("cpu", memory_format=torch.contiguous_format), out, cfg.input_size, meta, overwrite=overwrite)
    ckpt.unlink(missing_ok=True)
    return {"model": str(out), "steps": step, "train_time_s": train_time, "history": history}
