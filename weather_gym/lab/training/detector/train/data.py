"""Training samples: augmentation (:func:`augment`), the heatmap and box targets (:func:`build_targets`)
and the seeded dataset of training frames (every sample's generator from ``(seed, epoch, index)``).

Example:
    >>> import numpy as np
    >>> heat, ign, ind, size, off, mask = build_targets(np.array([[100., 100., 120., 140.]]), np.array([0]),
    ...                                                 np.array([False]), (512, 288), stride=8)[:6]
    >>> heat.shape, int(mask.sum())
    ((4, 36, 64), 1)
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import torch

from weather_gym.core.errors import InputError
from weather_gym.lab.training.detector.conenet import NUM_CLASSES, STRIDE
from weather_gym.lab.training.detector.train.config import MAX_OBJECTS, TrainConfig
from weather_gym.perception.augment import camera_look, paste_distractors
from weather_gym.perception.labels import hidden_mask
from weather_gym.perception.preprocess import PAD_VALUE, letterbox_params


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
            near = d < hdist[y0:y1, x0:x1]  # type: ignore[index]  # made with hreg
            hdist[y0:y1, x0:x1][near] = d[near]  # type: ignore[index]  # made with hreg
            for ch, v in enumerate((size[k - 1, 0], size[k - 1, 1], cx - gx, cy - gy)):
                hreg[ch, y0:y1, x0:x1][near] = np.broadcast_to(v, d.shape)[near]
            hmask[y0:y1, x0:x1][near] = 1.0  # type: ignore[index]  # made with hreg
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
