"""Ignore masks stored with a dataset: the ego vehicle and any region the user excludes.

A mask is a PNG the size of the frames; **white (>= 128) = ignored**, black = used. A dataset has at
most one dataset-wide mask, ``DIR/ignore_mask.png`` (named by ``info.ignore_mask`` in
``annotations.json``), and optionally one per frame (the image record's ``ignore_mask``, a path
inside the dataset); a frame's mask is the union of both. Every place that scores or compares frames
applies it: ground truth and detections inside it do not count (``weather_gym.perception.ignore``)
and the gap workflow's image signals skip its pixels.

:func:`propose_mask` finds the ego vehicle from the frames themselves: pixels that stay the same
while the scene moves, kept where they form a region touching the bottom of the frame (an onboard
camera sees the car's nose, wheels and steering wheel there; a static over-exposed sky touches the
top and is not the car). ``weather-gym dataset mask DIR --out MASK.png`` writes the proposal for a
person to check and edit; ``--set MASK.png`` stores an (edited) mask with the dataset.

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.datasets.masks import propose_mask
    >>> rng = np.random.default_rng(0)
    >>> frames = [rng.integers(0, 256, (60, 80, 3), dtype=np.uint8) for _ in range(6)]
    >>> for f in frames:
    ...     f[40:] = 90                                   # a static "bonnet" in the lower third
    >>> m = propose_mask(frames)
    >>> round(float(m[40:].mean()), 2), round(float(m[:30].mean()), 2)
    (1.0, 0.0)
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from weather_gym.core._io import atomic_write, atomic_write_json, resolve_inside
from weather_gym.core.errors import InputError, OutputExistsError
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.coco_files import ANNOTATIONS, read_mask

__all__ = ["MASK_FILE", "read_mask", "write_mask", "propose_mask", "mask_preview", "set_dataset_mask"]

MASK_FILE = "ignore_mask.png"
_WORK_WIDTH = 192


def _png(mask: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", np.where(np.asarray(mask, bool), 255, 0).astype(np.uint8))
    if not ok:
        raise InputError("could not encode the mask as PNG")
    return buf.tobytes()


def write_mask(path: str | os.PathLike, mask: np.ndarray, *, overwrite: bool = False) -> Path:
    """Write a boolean mask as an 8-bit PNG (255 = ignored), safely (never over an existing file
    unless ``overwrite``)."""
    m = np.asarray(mask)
    if m.ndim != 2 or m.size == 0:
        raise InputError(f"a mask must be a 2-D (H, W) array, got shape {m.shape}")
    return atomic_write(path, _png(m), overwrite=overwrite)


def _luma_stack(frames: Sequence[np.ndarray], width: int) -> np.ndarray:
    h0, w0 = frames[0].shape[:2]
    w = min(width, w0)
    h = max(int(round(h0 * w / w0)), 1)
    out = np.empty((len(frames), h, w), np.float32)
    for i, f in enumerate(frames):
        if f.shape[:2] != (h0, w0):
            raise InputError(f"frame {i} is {f.shape[1]}x{f.shape[0]}, frame 0 is {w0}x{h0}: a mask needs frames "
                             "of one size")
        y = cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY)
        out[i] = cv2.resize(y, (w, h), interpolation=cv2.INTER_AREA)
    return out


def propose_mask(frames: Sequence[np.ndarray], *, static_fraction: float = 0.45, min_area: float = 0.01,
                 dilate_px: int = 3) -> np.ndarray:
    """Propose an ego-vehicle mask (True = ignore) from frames of a moving camera.

    A pixel is *static* when its median absolute change from its own temporal median is below
    ``static_fraction`` of the typical change over the frame (the 75th percentile; and below 12
    grey levels). Static regions are cleaned (morphological opening and closing), the ones touching
    the bottom border and covering at least ``min_area`` of the frame are kept; below a kept pixel
    everything down to the bottom border is the car too (moving parts such as the steering wheel
    and the wheels' tread), holes are filled, and the result is grown by ``dilate_px`` pixels.
    Needs at least 4 frames in which the scene moves.
    """
    if len(frames) < 4:
        raise InputError(f"proposing a mask needs at least 4 frames, got {len(frames)}")
    h0, w0 = frames[0].shape[:2]
    y = _luma_stack(frames, _WORK_WIDTH)
    med = np.median(y, axis=0)
    mad = np.median(np.abs(y - med), axis=0)
    typical = float(np.percentile(mad, 75))
    if typical < 2.0:
        raise InputError(f"the {len(frames)} frames hardly change (75th percentile of the per-pixel change "
                         f"{typical:.2f} grey levels): the static ego vehicle cannot be told from the scene; "
                         "propose a mask from frames of a moving camera")
    static = (mad < min(static_fraction * typical, 12.0)).astype(np.uint8)
    k = np.ones((3, 3), np.uint8)
    static = cv2.morphologyEx(cv2.morphologyEx(static, cv2.MORPH_OPEN, k), cv2.MORPH_CLOSE, k)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(static, connectivity=4)
    hh, ww = static.shape
    keep = np.zeros_like(static)
    for c in range(1, n):
        x, yy, bw, bh, area = stats[c]
        if yy + bh >= hh and area >= min_area * hh * ww:
            keep[labels == c] = 1
    # below the car is car: fill each column from its topmost kept pixel down to the bottom
    cols = np.flatnonzero(keep.any(axis=0))
    if cols.size:
        top = np.argmax(keep[:, cols] > 0, axis=0)
        rows = np.arange(hh)[:, None]
        keep[:, cols] |= (rows >= top[None, :]).astype(np.uint8)  # type: ignore[misc]  # a uint8 mask
    # fill holes: everything not reachable from the top border through unkept pixels
    free = (1 - keep).astype(np.uint8)
    flood = free.copy()
    ff = np.zeros((hh + 2, ww + 2), np.uint8)
    for x in range(ww):
        if flood[0, x] == 1:
            cv2.floodFill(flood, ff, (x, 0), 2)
    keep[flood == 1] = 1
    mask = cv2.resize(keep * 255, (w0, h0), interpolation=cv2.INTER_LINEAR) >= 128
    if dilate_px > 0 and mask.any():
        d = 2 * int(dilate_px) + 1
        mask = cv2.dilate(mask.astype(np.uint8), np.ones((d, d), np.uint8)) > 0
    return mask


def mask_preview(frame: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``frame`` with the masked pixels tinted red and the mask's outline drawn (for checking a mask)."""
    out = frame.copy()
    m = np.asarray(mask, bool)
    out[m] = (0.45 * out[m] + 0.55 * np.array([255, 0, 0])).astype(np.uint8)
    contours, _ = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cv2.drawContours(out, contours, -1, (255, 255, 0), max(1, frame.shape[1] // 400))
    return out


def set_dataset_mask(root: str | os.PathLike, mask_path: str | os.PathLike, *, frame: str | None = None,
                     overwrite: bool = False) -> Path:
    """Store the mask PNG ``mask_path`` with the dataset in ``root`` (dataset-wide, or for the image
    whose ``file_name`` is ``frame``) and record it in ``annotations.json``; returns the stored file.

    The mask is checked against the frames' size first; an existing mask is replaced only with
    ``overwrite``.
    """

    ds = load_coco(root)
    root = Path(root)
    if frame is None:
        sizes = {(int(r["width"]), int(r["height"])) for r in ds.images}
        if len(sizes) != 1:
            raise InputError(f"{root}: frames have several sizes {sorted(sizes)}; a dataset-wide mask needs one "
                             "size (set per-frame masks with --frame)")
        size, rel, rec = next(iter(sizes)), MASK_FILE, None
    else:
        rec = next((r for r in ds.images if r["file_name"] == frame), None)
        if rec is None:
            raise InputError(f"{root / ANNOTATIONS}: no image with file_name {frame!r}")
        size = (int(rec["width"]), int(rec["height"]))
        rel = f"masks/{Path(frame).stem}.png"
    mask = read_mask(mask_path, size)
    dest = resolve_inside(root, rel, what=f"{root}: ignore mask")
    current = ds.data.get("info", {}).get("ignore_mask") if rec is None else rec.get("ignore_mask")
    if (current or dest.exists()) and not overwrite:
        raise OutputExistsError(f"{root} already has an ignore mask ({current or rel}); pass --overwrite to replace it")
    atomic_write(dest, _png(mask), overwrite=overwrite)
    data = json.loads((root / ANNOTATIONS).read_text())
    if rec is None:
        data.setdefault("info", {})["ignore_mask"] = rel
    else:
        next(r for r in data["images"] if r["file_name"] == frame)["ignore_mask"] = rel
    atomic_write_json(root / ANNOTATIONS, data, overwrite=True)  # the dataset's own index, one key added
    return dest
