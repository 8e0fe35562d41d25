"""The frames the gap workflow compares: a loaded set (:class:`FrameSet`), the measured and simulated
sets with their fitting / held-out split (:class:`GapData`), loading a COCO folder scaled once to the
comparison width, and the checks of whether two sets show the same views.

Example:
    >>> fit, held = split_indices(10, held_out=0.5, seed=0)
    >>> len(fit), len(held), sorted(fit.tolist() + held.tolist()) == list(range(10))
    (5, 5, True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError

_PAIRED_KEYS = ("track", "pose")
"""What every record of a paired set names: the views are rendered again from them."""

MIN_FRAMES = 8
"""Fewest frames per set the workflow accepts: half of them fit, half are held out, and a bootstrap
over fewer than four frames per half says nothing."""

COMPARE_WIDTH = 672
"""Frames wider than this are scaled down once, on loading, by the smallest whole factor that brings
them to at most this width (1024x768 -> 512x384; a whole factor averages exact pixel blocks): the
signals, effects and detector then work at about the simulator's own width."""


@dataclass
class FrameSet:
    """Frames in memory: RGB images, depth (metres or None), ground truth, effect state, image ids,
    ignore masks (True = ignored, or None), and how they were scaled on loading."""

    images: list[np.ndarray]
    depths: list[np.ndarray | None]
    gts: list[dict[str, np.ndarray]]
    states: list[dict[str, float]]
    ids: list[int]
    root: str
    masks: list[np.ndarray | None] = field(default_factory=list)
    scale: float = 1.0
    original_size: tuple[int, int] | None = None
    real: bool = False

    def __post_init__(self) -> None:
        if not self.masks:
            self.masks = [None] * len(self.images)

    def __len__(self) -> int:
        return len(self.images)

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` of the frames."""
        h, w = self.images[0].shape[:2]
        return w, h

    def shared_mask(self) -> np.ndarray | None:
        """The one ignore mask every frame has (a dataset-wide mask), else None."""
        ids = {id(m) for m in self.masks}
        return self.masks[0] if len(ids) == 1 and self.masks[0] is not None else None


@dataclass
class GapData:
    """Measured frames and the frames the model is applied to, with the fitting / held-out split.

    ``mode``: ``paired`` / ``unpaired`` (the clean simulator), ``same-camera`` (``sim`` holds the
    measured *clear* reference frames of the same camera; no simulator) or ``did``
    (difference-in-differences: ``sim`` holds the clean simulator frames, ``reference`` the measured
    clear frames). ``paired``: ``sim[i]`` shows the view of ``measured[i]`` (then the split indexes
    both); ``ref_paired``: ``reference[i]`` shows the view of ``measured[i]``.
    """

    mode: str
    mode_reason: str
    measured: FrameSet
    sim: FrameSet
    fit: np.ndarray
    held: np.ndarray
    sim_fit: np.ndarray
    sim_held: np.ndarray
    notes: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    reference: FrameSet | None = None
    ref_fit: np.ndarray | None = None
    ref_held: np.ndarray | None = None
    pairs: bool | None = None
    ref_paired: bool = False
    confounded: bool = False
    confounded_reason: str = ""

    @property
    def paired(self) -> bool:
        return self.mode == "paired" if self.pairs is None else bool(self.pairs)

    @property
    def did(self) -> bool:
        return self.mode == "did"

    def _set(self, which: str) -> FrameSet:
        return {"measured": self.measured, "sim": self.sim, "reference": self.reference}[which]  # type: ignore[return-value]  # asked only for a set the mode has

    def signal_depths(self, which: str) -> list[np.ndarray | None]:
        """Depth maps the image signals use for ``which`` ("measured", "sim" or "reference").

        Paired: the depth of the ``sim`` view for both sets (the same geometry for both sides).
        Otherwise each set's own depth when every frame of the compared sets has one, else None.
        """
        if self.paired and which != "reference":
            return self.sim.depths
        frames = self._set(which)
        others = [self.measured, self.sim] + ([self.reference] if self.reference is not None else [])
        have = all(d is not None for f in others for d in f.depths)
        return frames.depths if have else [None] * len(frames)

    def signal_boxes(self, which: str) -> list[np.ndarray]:
        """Cone boxes for the cone signals: the measured ground truth for both sets when paired."""
        frames = self.measured if (self.paired and which == "sim") else self._set(which)
        return [g["boxes"] for g in frames.gts]

    def signal_masks(self, which: str) -> list[np.ndarray | None]:
        """Ignore masks of the image signals: each set's own; simulator frames, which show no ego
        vehicle, skip the measured set's dataset-wide mask (so that both sides are compared on the
        same part of the frame); paired frames skip the measured frame's mask."""
        frames = self._set(which)
        if which == "sim":
            if self.paired:
                return self.measured.masks
            if self.mode in ("unpaired", "did") and frames.size == self.measured.size:
                shared = self.measured.shared_mask()
                if shared is not None:
                    return [shared] * len(frames)
        return frames.masks


def frame_state(record: dict, fx_scale: float = 1.0) -> dict[str, float]:
    """The weather ``state`` of a frame: ``speed``, ``yaw_rate`` and ``fx`` from its record (``fx``
    times ``fx_scale`` for a frame scaled on loading).

    The exposure time is deliberately left out: it is a parameter of the weather model (what the
    gap workflow fits), so ``motion_blur`` uses its own ``exposure_s``.
    """
    state = {"speed": float(record.get("speed", 0.0) or 0.0), "yaw_rate": float(record.get("yaw_rate", 0.0) or 0.0)}
    cam = record.get("camera")
    k = record.get("intrinsics")
    if cam:
        state["fx"] = CameraConfig(**cam).fx
    elif k:
        state["fx"] = float(k["fx"])
    else:
        state["fx"] = record["width"] / 2.0  # 90 degree field of view
    state["fx"] *= fx_scale
    if fx_scale < 1.0:
        state["binning"] = 1.0 / fx_scale  # the frame was scaled down from the sensor's pixels
    return state


def is_real(ds: Any) -> bool:
    """Whether a dataset looks like a real recording (imported, or records without a simulator track)
    rather than the simulator's own frames."""
    info = ds.info if hasattr(ds, "info") else {}
    if info.get("origin") in ("import", "external"):
        return True
    return not any(rec.get("track") for rec in ds.images)


def load_frames(ds: Any, *, max_width: int | None = None, progress: bool = False, desc: str = "load") -> FrameSet:
    """Read every frame of a ``CocoDataset`` into memory, scaled down once by a whole factor to at most
    ``max_width`` when wider (boxes, depth, ignore masks and focal length scaled with it)."""

    sizes = {(int(r["width"]), int(r["height"])) for r in ds.images}
    if len(sizes) > 1:
        raise InputError(f"{ds.annotations_path}: frames have different sizes {sorted(sizes)}; the gap workflow "
                         "needs one camera resolution")
    w0, h0 = next(iter(sizes))
    if max_width is not None and w0 > max_width:
        n = math.ceil(w0 / max_width)
        w1, h1 = max(w0 // n, 1), max(h0 // n, 1)
    else:
        w1, h1 = w0, h0
    sx, sy = w1 / w0, h1 / h0
    images, depths, gts, states, ids, masks = [], [], [], [], [], []
    scaled_masks: dict[int, np.ndarray] = {}
    for i in tqdm(range(len(ds)), desc=desc, unit="frame", disable=not progress):
        img = ds.image(i)
        if img.shape[:2] != (h0, w0):
            raise InputError(f"{ds.image_path(i)} is {img.shape[1]}x{img.shape[0]} but its record says {w0}x{h0}")
        depth = ds.depth(i)
        gt = ds.gt(i)
        mask = gt.pop("ignore_mask", None)
        if (w1, h1) != (w0, h0):
            img = cv2.resize(img, (w1, h1), interpolation=cv2.INTER_AREA)
            if depth is not None:
                depth = cv2.resize(depth, (w1, h1), interpolation=cv2.INTER_NEAREST)
            gt["boxes"] = (gt["boxes"] * np.array([sx, sy, sx, sy], np.float32)).astype(np.float32)
            if mask is not None:
                if id(mask) not in scaled_masks:
                    m = cv2.resize(mask.astype(np.uint8) * 255, (w1, h1), interpolation=cv2.INTER_AREA) >= 128
                    m.setflags(write=False)
                    scaled_masks[id(mask)] = m
                mask = scaled_masks[id(mask)]
        if mask is not None:
            gt["ignore_mask"] = mask
        images.append(np.ascontiguousarray(img))
        depths.append(depth)
        gts.append(gt)
        masks.append(mask)
        states.append(frame_state(ds.record(i), sx))
        ids.append(int(ds.record(i)["id"]))
    return FrameSet(images, depths, gts, states, ids, str(ds.root), masks, sx, (w0, h0), is_real(ds))


def same_views(a: FrameSet, b: FrameSet, *, threshold: float = 0.5) -> tuple[bool, float]:
    """Whether frame ``i`` of ``a`` and of ``b`` show the same view (one is the other with weather
    on it), and the score: the median over frame pairs of the median zero-normalised
    cross-correlation of 10x10 patches of luma at 160 px width (outside the ignore masks). Different
    frames of one drive score about 0.1, a frame and itself under heavy fog or blur above 0.5."""

    if len(a) != len(b) or a.size != b.size or not len(a):
        return False, math.nan
    w, h, p = 160, max(int(round(160 * a.size[1] / a.size[0])), 10), 10
    hh, ww = (h // p) * p, (w // p) * p

    def luma(img: np.ndarray) -> np.ndarray:
        return cv2.resize(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)

    def patches(x: np.ndarray) -> np.ndarray:
        return x[:hh, :ww].reshape(hh // p, p, ww // p, p).transpose(0, 2, 1, 3).reshape(-1, p * p)

    scores = []
    for ia, ib, ma, mb in zip(a.images, b.images, a.masks, b.masks):
        m = ma if ma is not None else mb
        keep = np.ones((h, w), bool) if m is None else cv2.resize(
            m.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) == 0
        pa, pb = patches(luma(ia)), patches(luma(ib))
        ok = patches(keep).all(1)
        pa, pb = pa - pa.mean(1, keepdims=True), pb - pb.mean(1, keepdims=True)
        na, nb = np.linalg.norm(pa, axis=1), np.linalg.norm(pb, axis=1)
        ok &= (na >= p) & (nb >= p)
        scores.append(float(np.median((pa[ok] * pb[ok]).sum(1) / (na[ok] * nb[ok]))) if ok.sum() >= 5 else 0.0)
    score = float(np.median(scores))
    return score >= threshold, score


def paired_check(ds: Any) -> tuple[bool, str]:
    """Whether every record of ``ds`` can be re-rendered, and why (not)."""
    missing: dict[str, int] = {}
    for rec in ds.images:
        for key in _PAIRED_KEYS:
            if rec.get(key) is None:
                missing[key] = missing.get(key, 0) + 1
    if missing:
        what = ", ".join(f"{k!r} missing in {n} of {len(ds)} records" for k, n in missing.items())
        return False, f"poses absent ({what}): distributions over the whole sets are compared"
    return True, f"every record has a track and a car pose: each of the {len(ds)} views is re-rendered"


def split_indices(n: int, *, held_out: float = 0.5, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A seeded split of ``range(n)`` into (fitting, held-out) index arrays, each sorted."""
    if not 0.0 < held_out < 1.0:
        raise InputError(f"held_out must be a fraction in (0, 1), got {held_out}")
    if n < 4:
        raise InputError(f"the gap workflow needs at least 4 frames, got {n}")
    perm = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5917])).permutation(n)
    n_held = min(max(int(round(n * held_out)), 2), n - 2)
    return np.sort(perm[n_held:]), np.sort(perm[:n_held])
