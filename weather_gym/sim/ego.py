"""The ego car's own nose, front wheels and steering wheel in the lower part of the camera frame
(an overlay composited after rendering, as a camera mounted behind the driver sees them).

The overlay is drawn procedurally per variant (``Look.ego_seed`` in ``[0, EGO_VARIANTS)``; -1 = no
overlay) and image size. Pixels under it are never cones: the segmentation there is -1, and the
ground truth from geometry is cut at the overlay's top edge (:func:`clip_ground_truth`): a cone whose
box lies wholly behind the car is dropped, one partly behind keeps only its visible part.

Example:
    >>> from weather_gym.sim.ego import ego_overlay
    >>> ov = ego_overlay(3, 160, 90)
    >>> ov.mask.shape, bool(ov.mask[-1].all()), bool(ov.mask[0].any())
    ((90, 160), True, False)
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.errors import InputError

EGO_VARIANTS = 16
"""Number of distinct ego-car overlays (``Look.ego_seed`` in ``[0, EGO_VARIANTS)``)."""
EGO_DEPTH_M = 0.8
"""Depth (m) reported under the overlay."""

_BODY = ((236, 236, 232), (200, 28, 30), (24, 24, 26), (30, 50, 120), (170, 172, 176), (240, 240, 240),
         (40, 40, 44), (210, 210, 214))


@dataclass(frozen=True)
class EgoOverlay:
    """``rgb`` (H, W, 3) uint8 and ``mask`` (H, W) bool of the car's parts; ``top`` (W,) the first
    masked row of each column (H where a column is free)."""

    rgb: np.ndarray
    mask: np.ndarray
    top: np.ndarray

    @functools.cached_property
    def top_min(self) -> int:
        """The overlay's highest row (H when it is empty)."""
        return int(self.top.min()) if self.top.size else int(self.mask.shape[0])


@functools.lru_cache(maxsize=32)
def ego_overlay(variant: int, width: int, height: int) -> EgoOverlay:
    """The overlay of ``variant`` at ``width`` x ``height`` (cached; the arrays are read-only)."""
    if not 0 <= int(variant) < EGO_VARIANTS:
        raise InputError(f"ego overlay variant must lie in [0, {EGO_VARIANTS}), got {variant}")
    rng = np.random.default_rng([int(variant), 31])
    W, H = int(width), int(height)
    s = 4  # draw at 4x and downsample: anti-aliased edges
    w, h = W * s, H * s
    img = np.zeros((h, w, 3), np.float32)
    cov = np.zeros((h, w), np.float32)
    frac = float(rng.uniform(0.28, 0.45))  # how much of the frame height the car covers
    y_top = h * (1 - frac)
    cx = w * (0.5 + float(rng.uniform(-0.03, 0.03)))
    body = np.array(_BODY[int(rng.integers(len(_BODY)))], np.float32)
    dark = np.array([22.0, 22.0, 24.0])

    def poly(pts, colour, grad: float = 0.0):
        m = np.zeros((h, w), np.uint8)
        cv2.fillPoly(m, [np.round(np.asarray(pts)).astype(np.int32)], 1)
        sel = m.astype(bool)
        rows = np.arange(h, dtype=np.float32)[:, None]
        shade = 1.0 - grad * (rows - y_top) / max(h - y_top, 1)  # darker towards the bottom
        col = np.asarray(colour, np.float32)[None, None, :] * np.clip(shade, 0.3, 1.2)[..., None]
        img[sel] = np.broadcast_to(col, (h, w, 3))[sel]
        cov[sel] = 1.0

    # front wheels: black tyres at the lower corners, partly out of the frame
    ww = w * float(rng.uniform(0.2, 0.28))
    wt = h - (h - y_top) * float(rng.uniform(0.75, 1.1))
    for side in (-1, 1):
        xc = cx + side * w * float(rng.uniform(0.40, 0.48))
        # the tyre: a rounded slab seen from above and behind (tread lit on top, darker sidewall)
        ay = (h - wt) * 1.1
        for k, (shrink, col) in enumerate(((1.0, dark * 1.2), (0.8, dark * 1.9))):
            axes = (int(ww / 2 * shrink), int(ay * (1.0 if k == 0 else 0.9)))
            centre = (int(xc), int(wt + ay))
            cv2.ellipse(img, centre, axes, 0, 0, 360, col.tolist(), -1, cv2.LINE_AA)
            cv2.ellipse(cov, centre, axes, 0, 0, 360, 1.0, -1, cv2.LINE_AA)
        cv2.ellipse(img, (int(xc), int(wt + ay)), (int(ww * 0.3), int(ay * 0.75)), 0, 200, 340,
                    (dark * 0.6).tolist(), max(1, s), cv2.LINE_AA)  # a tread groove
        # suspension arms from the nose to the wheel
        for k in (0.25, 0.55):  # type: ignore[assignment]  # k: a fraction here
            y = wt + (h - wt) * k
            cv2.line(img, (int(cx + side * w * 0.12), int(y_top + (h - y_top) * (0.2 + k * 0.3))),
                     (int(xc - side * ww / 2), int(y)), (35, 35, 38), max(2, 2 * s), cv2.LINE_AA)
            cv2.line(cov, (int(cx + side * w * 0.12), int(y_top + (h - y_top) * (0.2 + k * 0.3))),
                     (int(xc - side * ww / 2), int(y)), 1.0, max(2, 2 * s), cv2.LINE_AA)
    # the nose: a trapezoid from the cockpit to the front, lighter along its centre
    top_w = w * float(rng.uniform(0.14, 0.24))
    bot_w = w * float(rng.uniform(0.62, 0.82))
    poly([(cx - top_w / 2, y_top), (cx + top_w / 2, y_top), (cx + bot_w / 2, h), (cx - bot_w / 2, h)], body, grad=0.35)
    poly([(cx - top_w * 0.3, y_top + 2 * s), (cx + top_w * 0.3, y_top + 2 * s), (cx + bot_w * 0.2, h),
          (cx - bot_w * 0.2, h)], np.minimum(body * 1.12 + 10, 255), grad=0.3)
    if rng.random() < 0.7:  # a number board near the tip
        bw, bh = top_w * 0.8, (h - y_top) * 0.12
        y0 = y_top + (h - y_top) * 0.08
        poly([(cx - bw / 2, y0), (cx + bw / 2, y0), (cx + bw / 2, y0 + bh), (cx - bw / 2, y0 + bh)], (235, 235, 235))
        for k in (-1, 1):  # two "digits"
            dx = cx + k * bw * 0.18
            cv2.rectangle(img, (int(dx - bw * 0.08), int(y0 + bh * 0.2)), (int(dx + bw * 0.08), int(y0 + bh * 0.8)),
                          (20, 20, 20), max(1, s), cv2.LINE_AA)
    # cockpit rim and, for some variants, the steering wheel
    rim = h - (h - y_top) * float(rng.uniform(0.25, 0.4))
    poly([(cx - bot_w * 0.45, h), (cx - bot_w * 0.38, rim), (cx + bot_w * 0.38, rim), (cx + bot_w * 0.45, h)],
         dark * 1.6, grad=0.2)
    if rng.random() < 0.6:
        sw = w * float(rng.uniform(0.18, 0.28))
        st = rim - (h - y_top) * 0.12
        cv2.ellipse(img, (int(cx), int(h + sw * 0.2)), (int(sw / 2), int(h + sw * 0.2 - st)), 0, 180, 360,
                    (18, 18, 20), int(sw * 0.12), cv2.LINE_AA)
        cv2.ellipse(cov, (int(cx), int(h + sw * 0.2)), (int(sw / 2), int(h + sw * 0.2 - st)), 0, 180, 360,
                    1.0, int(sw * 0.12), cv2.LINE_AA)
        for k, col in enumerate(((200, 30, 30), (240, 240, 240), (40, 200, 60))):  # type: ignore[assignment]  # buttons (col: an RGB tuple here)
            cv2.circle(img, (int(cx + (k - 1) * sw * 0.15), int(rim + 6 * s)), 3 * s, col, -1, cv2.LINE_AA)  # type: ignore[call-overload]  # col: RGB
    img *= 1 + 0.03 * rng.standard_normal((h, w, 1)).astype(np.float32)
    rgb = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA)
    alpha = cv2.resize(cov, (W, H), interpolation=cv2.INTER_AREA)
    mask = alpha > 0.5
    rgb = np.clip(rgb / np.maximum(alpha, 1e-3)[..., None], 0, 255).astype(np.uint8)
    rgb[~mask] = 0
    top = np.where(mask.any(axis=0), mask.argmax(axis=0), H).astype(np.int64)
    for a in (rgb, mask, top):
        a.flags.writeable = False
    return EgoOverlay(rgb=rgb, mask=mask, top=top)


def composite(rgb: np.ndarray, overlay: EgoOverlay) -> None:
    """Paint the overlay into ``rgb`` in place."""
    np.copyto(rgb, overlay.rgb, where=overlay.mask[..., None])


def clip_ground_truth(gt: ConeArrays, overlay: EgoOverlay) -> ConeArrays:
    """Cut the cones' boxes (xyxy, pixel edges) at the overlay's top edge; drop the ones it hides.
    The visible pixel count shrinks in proportion to the box height kept."""
    if gt.count == 0:
        return gt
    given = np.asarray(gt["boxes"], np.float32)
    # a box whose bottom is above the overlay's highest row is never cut (the limit below is >= that row)
    reach = np.flatnonzero(given[:, 3] > overlay.top_min)
    if reach.size == 0:
        return gt
    boxes = given.copy()
    keep = np.ones(len(boxes), bool)
    W = overlay.top.shape[0]
    for i in reach.tolist():
        x0, y0, x1, y1 = boxes[i]
        c0, c1 = int(max(0, np.floor(x0))), int(min(W, np.ceil(x1)))
        if c1 <= c0:
            continue
        limit = float(overlay.top[c0:c1].max())  # the lowest free row across the box's columns
        if limit <= y0:
            keep[i] = False
        elif limit < y1:
            boxes[i, 3] = limit
    if keep.all() and np.array_equal(boxes, gt["boxes"]):
        return gt
    out = {k: np.asarray(v)[keep] for k, v in gt.items()}
    old = np.asarray(gt["boxes"], np.float32)[keep]
    out["boxes"] = boxes[keep]
    if "pixels" in out:
        h_old = np.maximum(old[:, 3] - old[:, 1], 1e-6)
        kept = (boxes[keep][:, 3] - boxes[keep][:, 1]) / h_old
        out["pixels"] = np.maximum(1, np.round(np.asarray(out["pixels"]) * kept)).astype(np.int64)
    return ConeArrays(out)
