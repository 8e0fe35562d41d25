"""Per-frame image signals: the fingerprints different weather effects leave in a frame.

Each frame becomes a vector of :data:`SIGNALS` (float64, NaN where a signal is undefined, e.g. no
cone in view). Every signal targets one kind of change and is, where it can be, blind to the others:
sharpness and contrast signals are divided by the frame's own contrast, so dimming alone does not
move them; noise is measured in flat regions only; block artefacts are a ratio on the 8-pixel JPEG
grid. Most are computed at half or quarter resolution; those that need every pixel (noise, fine
sharpness, blockiness) at full resolution.

=========  ==================================================================================
family     signals
=========  ==================================================================================
tone       ``brightness`` (mean luma), ``tone_p05`` / ``tone_p50`` / ``tone_p95`` (luma
           percentiles), ``contrast`` (luma std)
colour     ``color_rg``, ``color_bg`` (log channel ratios), ``saturation``
sharpness  ``sharp_fine`` (Laplacian energy), ``sharp_half``, ``sharp_quarter`` (gradient energy
           at 1/2 and 1/4 scale), all over the luma variance (log); ``edge_p99`` (strong edges
           over the luma range)
motion     ``motion_dir`` (horizontal over vertical gradient energy: sideways smear),
           ``radial_sharp`` (periphery over centre gradient energy: zoom blur),
           ``sharp_near_far`` (sharpness near over far: the car's motion smears near things)
noise      ``noise_flat`` (Immerkaer's estimate in flat regions, log), ``noise_dark`` /
           ``noise_bright`` (the same in the darkest / brightest third of the flat pixels)
block      ``blockiness`` (luma steps on the 8 px grid over steps elsewhere), ``block_chroma``
           (the same for chroma on the 16 px grid of 4:2:0 subsampling)
haze       ``haze_lift`` (far over near mean luma), ``haze_contrast`` (far over near luma std),
           from the depth map (rows as a fallback)
vignette   ``vignette`` (corner over centre luma)
blobs      ``bright_flat`` (fraction of bright, featureless tiles: droplets, glare)
cones      ``cone_contrast`` (cone colour against its surroundings), ``cone_sharp`` (gradient
           energy inside the boxes over their variance)
=========  ==================================================================================

**Ignore masks.** ``frame_signals(..., mask=M)`` (``M`` True = ignored, e.g. the ego vehicle) skips
the masked pixels in every signal (a pixel next to the mask's edge too, where a filter would reach
into it); :func:`signal_mask` prepares a mask once for many frames.

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.gap.signals import SIGNAL_NAMES, frame_signals
    >>> img = np.random.default_rng(0).integers(0, 256, (64, 96, 3), dtype=np.uint8)
    >>> v = frame_signals(img)
    >>> v.shape == (len(SIGNAL_NAMES),), bool(120 < v[SIGNAL_NAMES.index("brightness")] < 135)
    (True, True)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.perception.ignore import inside_mask

__all__ = ["SIGNALS", "SIGNAL_NAMES", "FAMILIES", "Signal", "SignalMask", "signal_mask", "frame_signals",
           "signal_table", "signal_weights"]


@dataclass(frozen=True)
class Signal:
    """One image signal: its ``family`` (the kind of effect it reacts to), the smallest spread
    ``floor`` used when standardising it, and what it measures."""

    name: str
    family: str
    floor: float
    doc: str


SIGNALS: tuple[Signal, ...] = (
    Signal("brightness", "tone", 0.5, "mean luma (0-255)"),
    Signal("tone_p05", "tone", 0.5, "5th percentile of luma"),
    Signal("tone_p50", "tone", 0.5, "median luma"),
    Signal("tone_p95", "tone", 0.5, "95th percentile of luma"),
    Signal("contrast", "tone", 0.5, "luma standard deviation"),
    Signal("color_rg", "colour", 0.01, "log mean red / mean green"),
    Signal("color_bg", "colour", 0.01, "log mean blue / mean green"),
    Signal("saturation", "colour", 0.005, "mean (max - min) / max of RGB"),
    Signal("sharp_fine", "sharpness", 0.02, "log Laplacian energy / luma variance, full resolution"),
    Signal("sharp_half", "sharpness", 0.02, "log gradient energy / luma variance, half resolution"),
    Signal("sharp_quarter", "sharpness", 0.02, "log gradient energy / luma variance, quarter resolution"),
    Signal("edge_p99", "sharpness", 0.02, "log 99th percentile gradient / luma range"),
    Signal("motion_dir", "motion", 0.02, "log horizontal / vertical gradient energy"),
    Signal("radial_sharp", "motion", 0.02, "log periphery / centre gradient energy"),
    Signal("sharp_near_far", "motion", 0.02, "log sharpness near (< 6 m) / far (> 15 m)"),
    Signal("noise_flat", "noise", 0.03, "log noise sigma in flat regions (Immerkaer)"),
    Signal("noise_dark", "noise", 0.03, "log noise sigma, darkest third of the flat pixels"),
    Signal("noise_bright", "noise", 0.03, "log noise sigma, brightest third of the flat pixels"),
    Signal("blockiness", "block", 0.01, "log luma steps on the 8 px grid / steps elsewhere"),
    Signal("block_chroma", "block", 0.01, "log chroma steps on the 16 px grid / steps elsewhere"),
    Signal("haze_lift", "haze", 0.01, "log mean luma far / near (depth > 15 m vs < 6 m)"),
    Signal("haze_contrast", "haze", 0.01, "log luma std far / near"),
    Signal("vignette", "vignette", 0.005, "log mean luma in the corners / centre"),
    Signal("bright_flat", "blobs", 0.002, "fraction of bright featureless 8x8 tiles"),
    Signal("cone_contrast", "cones", 0.01, "log colour distance cone - surroundings / surroundings luma"),
    Signal("cone_sharp", "cones", 0.02, "log gradient energy / variance inside cone boxes"),
)

SIGNAL_NAMES: tuple[str, ...] = tuple(s.name for s in SIGNALS)
FAMILIES: tuple[str, ...] = tuple(dict.fromkeys(s.family for s in SIGNALS))

_LUMA = np.array([0.299, 0.587, 0.114], np.float64)
_IMMERKAER = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
_NOISE_SCALE = math.sqrt(math.pi / 2.0) / 6.0
_NOISE_FLOOR = 0.5  # code values: noise below this is invisible after 8-bit quantisation
_MIN_PIXELS = 200
_NEAR_M, _FAR_M = 6.0, 15.0
_MIN_CONE_PX = 8.0


def signal_weights() -> np.ndarray:
    """Weight of each signal in the gap: every family weighs 1, shared evenly by its signals."""
    counts = {f: sum(s.family == f for s in SIGNALS) for f in FAMILIES}
    return np.array([1.0 / counts[s.family] for s in SIGNALS])


def _log_ratio(a: float, b: float, eps: float) -> float:
    return math.log((a + eps) / (b + eps))


def _mean(a: np.ndarray, mask: np.ndarray | None = None) -> float:
    return float(cv2.mean(a, mask)[0])


def _grad(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared x and y gradients (Sobel, normalised to per-pixel steps)."""
    gx = cv2.Sobel(y, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(y, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    return cv2.multiply(gx, gx), cv2.multiply(gy, gy)


def _hist_quantile(cdf: np.ndarray, q: float) -> float:
    """Quantile of 8-bit values from their cumulative histogram, interpolated within the bin
    (each level spread evenly over [level - 0.5, level + 0.5]) so that it moves smoothly."""
    i = int(np.searchsorted(cdf, q))
    below = float(cdf[i - 1]) if i > 0 else 0.0
    width = float(cdf[i]) - below
    return i - 0.5 + ((q - below) / width if width > 0 else 0.5)


def _quantile(a: np.ndarray, q: float) -> float:
    """Approximate quantile from a strided sample (every 2nd row and column)."""
    sample = np.ascontiguousarray(a[::2, ::2]).ravel()
    k = min(int(q * (sample.size - 1)), sample.size - 1)
    return float(np.partition(sample, k)[k])


@lru_cache(maxsize=8)
def _radial_masks(h: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """uint8 masks (centre r < 0.35, periphery r > 0.6, corners r > 0.85), r = distance / half-diagonal."""
    yy, xx = np.mgrid[0:h, 0:w]
    r = np.hypot((xx + 0.5 - w / 2) / (w / 2), (yy + 0.5 - h / 2) / (h / 2)) / math.sqrt(2.0)
    masks = tuple((m.astype(np.uint8) * 255) for m in (r < 0.35, r > 0.6, r > 0.85))
    for m in masks:
        m.setflags(write=False)
    return masks


def _step_pairs(valid: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Per axis (columns, rows): float32 weights of the steps between two used pixels, and their counts."""
    out = []
    for axis in (1, 0):
        va, vb = (valid[:, 1:], valid[:, :-1]) if axis == 1 else (valid[1:], valid[:-1])
        pair = ((va > 0) & (vb > 0)).astype(np.float32)
        out.append((pair, cv2.reduce(pair, 1 - axis, cv2.REDUCE_SUM).ravel()))
    return tuple(out)


def _grid_steps(y: np.ndarray, period: int, pairs: tuple | None = None) -> float:
    """log (mean |step| across the ``period`` grid / mean |step| elsewhere), columns and rows averaged;
    ``pairs`` (from :func:`_step_pairs`): only steps between two used pixels count."""
    out = []
    for axis in (1, 0):
        n = y.shape[axis]
        if n <= period + 1:
            continue
        a, b = (y[:, 1:], y[:, :-1]) if axis == 1 else (y[1:], y[:-1])
        d = cv2.absdiff(a, b)
        if pairs is None:
            steps = cv2.reduce(d, 1 - axis, cv2.REDUCE_AVG).ravel()  # step j: between j and j + 1
            ok = np.ones(steps.shape[0], bool)
        else:
            pair, den = pairs[0 if axis == 1 else 1]
            num = cv2.reduce(cv2.multiply(d, pair), 1 - axis, cv2.REDUCE_SUM).ravel()
            ok = den >= 4
            steps = np.where(ok, num / np.maximum(den, 1.0), 0.0)
        on = np.zeros(steps.shape[0], bool)
        on[period - 1::period] = True
        if not (on & ok).any() or not (~on & ok).any():
            continue
        out.append(_log_ratio(float(steps[on & ok].mean()), float(steps[~on & ok].mean()), 0.05))
    return float(np.mean(out)) if out else math.nan


def _noise(y: np.ndarray, yh: np.ndarray, valid: np.ndarray | None = None) -> tuple[float, float, float]:
    """Noise sigma (log) in flat regions: all, darkest third, brightest third.

    Immerkaer's response is taken at full resolution and averaged over 2x2 blocks; the flat regions
    (lowest 30 % of local structure, clipped pixels excluded) are found at half resolution on a
    smoothed image, so that the noise itself does not decide what is flat.
    """
    hh, ww = yh.shape
    resp = cv2.absdiff(cv2.filter2D(y, cv2.CV_32F, _IMMERKAER, borderType=cv2.BORDER_REFLECT), 0.0)  # type: ignore[call-overload]  # cv2's stubs lack the scalar operand
    resp = cv2.resize(resp[:2 * hh, :2 * ww], (ww, hh), interpolation=cv2.INTER_AREA)
    local = cv2.blur(yh, (3, 3))
    gx, gy = _grad(local)
    structure = cv2.add(gx, gy)
    usable = (local > 3.0) & (local < 250.0)
    if valid is not None:
        usable &= valid > 0
    n_usable = int(np.count_nonzero(usable))
    if n_usable < _MIN_PIXELS:
        return math.nan, math.nan, math.nan
    su = structure[usable]
    thr = float(np.partition(su, int(0.3 * (su.size - 1)))[int(0.3 * (su.size - 1))])
    flat = usable & (structure <= thr)
    lv, rv = local[flat], resp[flat]
    if lv.size < _MIN_PIXELS // 4:
        return math.nan, math.nan, math.nan
    t1, t2 = lv.size // 3, lv.size - 1 - lv.size // 3
    lo, hi = np.partition(lv, (t1, t2))[[t1, t2]]

    def sig(r: np.ndarray) -> float:
        return math.log(_NOISE_SCALE * float(r.mean()) + _NOISE_FLOOR) if r.size >= _MIN_PIXELS // 8 else math.nan

    return sig(rv), sig(rv[lv <= lo]), sig(rv[lv >= hi])


def _depth_bins(depth: np.ndarray | None, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """uint8 masks (near, far) at ``shape``: from depth when given, else from image rows."""
    h, w = shape
    if depth is not None:
        d = cv2.resize(depth.astype(np.float32, copy=False), (w, h), interpolation=cv2.INTER_NEAREST)
        far_plane = float(d.max())
        near, far = d < _NEAR_M, (d >= _FAR_M) & (d < 0.95 * far_plane)
    else:
        rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
        near, far = rows >= 0.75 * h, (rows >= 0.40 * h) & (rows < 0.52 * h)
    return near.astype(np.uint8) * 255, far.astype(np.uint8) * 255


def _and(a: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    return a if valid is None else cv2.bitwise_and(a, valid)


def _masked_sharpness(energy: np.ndarray, y: np.ndarray, mask: np.ndarray) -> float:
    mean, std = cv2.meanStdDev(y, mask=mask)
    return _log_ratio(_mean(energy, mask), float(std[0, 0]) ** 2, 1.0)


def _cones(y: np.ndarray, rgb: np.ndarray, boxes: np.ndarray | None,
           ignored: np.ndarray | None = None) -> tuple[float, float]:
    if boxes is None or len(boxes) == 0:
        return math.nan, math.nan
    if ignored is not None:
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        boxes = boxes[~inside_mask(ignored, boxes)]
    h, w = y.shape
    contrast, sharp = [], []
    for x1, y1, x2, y2 in np.asarray(boxes, dtype=np.float64).reshape(-1, 4):
        if y2 - y1 < _MIN_CONE_PX or x2 - x1 < 2:
            continue
        bx1, by1 = max(int(math.floor(x1)), 0), max(int(math.floor(y1)), 0)
        bx2, by2 = min(int(math.ceil(x2)), w), min(int(math.ceil(y2)), h)
        if bx2 - bx1 < 3 or by2 - by1 < 5:
            continue
        mx, my = max((bx2 - bx1) // 2, 2), max((by2 - by1) // 4, 2)
        rx1, ry1, rx2, ry2 = max(bx1 - mx, 0), max(by1 - my, 0), min(bx2 + mx, w), min(by2 + my, h)
        n_ring = (ry2 - ry1) * (rx2 - rx1) - (by2 - by1) * (bx2 - bx1)
        if n_ring < 4:
            continue
        ring_sum = np.asarray(cv2.sumElems(rgb[ry1:ry2, rx1:rx2])[:3]) - np.asarray(
            cv2.sumElems(rgb[by1:by2, bx1:bx2])[:3])
        ring_mean = ring_sum / n_ring
        dx, dy = (bx2 - bx1) // 5, (by2 - by1) // 5
        core = np.asarray(cv2.mean(rgb[by1 + dy:by2 - dy, bx1 + dx:bx2 - dx])[:3])
        dist = float(np.linalg.norm(core - ring_mean))
        contrast.append(math.log(dist + 1.0) - math.log(float(ring_mean @ _LUMA) + 1.0))
        patch = y[by1:by2, bx1:bx2]
        gx, gy = _grad(patch)
        sharp.append(_log_ratio(_mean(cv2.add(gx, gy)), float(patch.var()), 1.0))
    if not contrast:
        return math.nan, math.nan
    return float(np.mean(contrast)), float(np.mean(sharp))


@dataclass(frozen=True)
class SignalMask:
    """The pixels the signals use (uint8, 255 = used) at full, half and quarter resolution, each
    shrunk by one pixel so that no filter reaches into the ignored region; ``ignored``: the mask."""

    ignored: np.ndarray
    full: np.ndarray
    half: np.ndarray
    quarter: np.ndarray
    tiles: np.ndarray
    pairs: tuple = ()

    @property
    def used_fraction(self) -> float:
        return float(np.count_nonzero(self.full)) / self.full.size


def signal_mask(mask: np.ndarray | None) -> SignalMask | None:
    """Prepare an ignore mask (True = ignored, ``H x W``) for :func:`frame_signals` (None: no mask)."""
    if mask is None:
        return None
    ignored = np.asarray(mask, bool)
    if not ignored.any():
        return None
    h, w = ignored.shape
    used = np.where(ignored, 0, 255).astype(np.uint8)
    k = np.ones((3, 3), np.uint8)

    def level(width: int, height: int) -> np.ndarray:
        m = cv2.resize(used, (width, height), interpolation=cv2.INTER_AREA)
        return cv2.erode(np.where(m >= 255, 255, 0).astype(np.uint8), k, borderType=cv2.BORDER_REPLICATE)

    full = cv2.erode(used, k, borderType=cv2.BORDER_REPLICATE)
    half = level(w // 2, h // 2)
    th, tw = (h // 2) // 8, (w // 2) // 8
    tiles = cv2.resize(half[:th * 8, :tw * 8], (tw, th), interpolation=cv2.INTER_AREA) >= 255 if th and tw else \
        np.zeros((0, 0), bool)
    out = SignalMask(ignored, full, half, level(w // 4, h // 4), tiles, _step_pairs(full))
    for a in (out.ignored, out.full, out.half, out.quarter, out.tiles):
        a.setflags(write=False)
    return out


def _masked_var(a: np.ndarray, valid: np.ndarray | None) -> float:
    if valid is None:
        return float(a.var())
    _, std = cv2.meanStdDev(a, mask=valid)
    return float(std[0, 0]) ** 2


def frame_signals(image: np.ndarray, depth: np.ndarray | None = None,
                  boxes: np.ndarray | None = None, mask: np.ndarray | SignalMask | None = None) -> np.ndarray:
    """The signal vector of one RGB uint8 frame (order of :data:`SIGNAL_NAMES`).

    ``depth``: z-depth in metres (``H x W``) for the haze and near/far signals (rows are used
    without it); ``boxes``: ground-truth cone boxes ``(K, 4)`` xyxy for the cone signals (NaN
    without them); ``mask``: ignored pixels (True; or a prepared :class:`SignalMask`).
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        got = f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__
        raise InputError(f"frame_signals: expected an RGB uint8 image (H, W, 3), got {got}")
    h, w = image.shape[:2]
    if h < 32 or w < 32:
        raise InputError(f"frame_signals: image {w}x{h} is too small (at least 32x32)")
    image = np.ascontiguousarray(image)
    sm = mask if isinstance(mask, SignalMask) or mask is None else signal_mask(mask)
    if sm is not None and sm.ignored.shape != (h, w):
        raise InputError(f"frame_signals: mask is {sm.ignored.shape[1]}x{sm.ignored.shape[0]}, the image {w}x{h}")
    vf, vh, vq = (None, None, None) if sm is None else (sm.full, sm.half, sm.quarter)
    y8 = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    y = y8.astype(np.float32)
    half = cv2.resize(image, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    yh = cv2.resize(y, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    yq = cv2.resize(yh, (w // 4, h // 4), interpolation=cv2.INTER_AREA)
    out: dict[str, float] = {}

    # tone
    hist = cv2.calcHist([y8], [0], vf, [256], [0, 256]).ravel().astype(np.float64)
    cdf = np.cumsum(hist) / max(hist.sum(), 1.0)
    mean, std = cv2.meanStdDev(y, mask=vf)
    out["brightness"] = float(mean[0, 0])
    for q, name in ((0.05, "tone_p05"), (0.5, "tone_p50"), (0.95, "tone_p95")):
        out[name] = _hist_quantile(cdf, q)
    out["contrast"] = float(std[0, 0])

    # colour
    m = cv2.mean(half, vh)
    out["color_rg"] = _log_ratio(m[0], m[1], 1.0)
    out["color_bg"] = _log_ratio(m[2], m[1], 1.0)
    out["saturation"] = _mean(cv2.cvtColor(half, cv2.COLOR_RGB2HSV)[..., 1], vh) / 255.0

    # sharpness over the contrast of the frame, so that a global gain does not move it
    var_f, var_h, var_q = float(std[0, 0]) ** 2, _masked_var(yh, vh), _masked_var(yq, vq)
    lap = cv2.Laplacian(y, cv2.CV_32F, ksize=1)
    out["sharp_fine"] = _log_ratio(_mean(cv2.multiply(lap, lap), vf), var_f, 1e-3)
    gxh, gyh = _grad(yh)
    energy = cv2.add(gxh, gyh)
    out["sharp_half"] = _log_ratio(_mean(energy, vh), var_h, 1e-3)
    gxq, gyq = _grad(yq)
    out["sharp_quarter"] = _log_ratio(_mean(cv2.add(gxq, gyq), vq), var_q, 1e-3)
    gmag = cv2.sqrt(energy)
    ghist = cv2.calcHist([gmag], [0], vh, [512], [0, 128]).ravel()
    p99 = float(np.searchsorted(np.cumsum(ghist) / max(ghist.sum(), 1.0), 0.99)) * 0.25
    out["edge_p99"] = _log_ratio(p99, out["tone_p95"] - out["tone_p05"], 1.0)

    # motion: direction of the smear, and where it is (periphery, near)
    centre, periphery, corners = (_and(m_, vh) for m_ in _radial_masks(*yh.shape))
    out["motion_dir"] = _log_ratio(_mean(gxh, vh), _mean(gyh, vh), 1e-3)
    radial_ok = cv2.countNonZero(periphery) >= _MIN_PIXELS and cv2.countNonZero(centre) >= _MIN_PIXELS
    out["radial_sharp"] = (_log_ratio(_mean(energy, periphery), _mean(energy, centre), 1e-3)
                           if radial_ok else math.nan)
    near, far = (_and(m_, vh) for m_ in _depth_bins(depth, yh.shape))
    n_near, n_far = cv2.countNonZero(near), cv2.countNonZero(far)
    both = n_near >= _MIN_PIXELS and n_far >= _MIN_PIXELS
    out["sharp_near_far"] = (_masked_sharpness(energy, yh, near) - _masked_sharpness(energy, yh, far)
                             if both else math.nan)

    # noise in flat regions
    out["noise_flat"], out["noise_dark"], out["noise_bright"] = _noise(y, yh, vh)

    # block artefacts (full resolution: the grid is in original pixels)
    pairs = None if sm is None else sm.pairs
    out["blockiness"] = _grid_steps(y, 8, pairs)
    out["block_chroma"] = _grid_steps(cv2.subtract(image[..., 0].astype(np.float32), y), 16, pairs)

    # haze: far against near
    if both:
        mn, sn = cv2.meanStdDev(yh, mask=near)
        mf, sf = cv2.meanStdDev(yh, mask=far)
        out["haze_lift"] = _log_ratio(float(mf[0, 0]), float(mn[0, 0]), 1.0)
        out["haze_contrast"] = _log_ratio(float(sf[0, 0]), float(sn[0, 0]), 1.0)
    else:
        out["haze_lift"] = out["haze_contrast"] = math.nan

    vig_ok = cv2.countNonZero(corners) >= _MIN_PIXELS // 4 and cv2.countNonZero(centre) >= _MIN_PIXELS
    out["vignette"] = _log_ratio(_mean(yh, corners), _mean(yh, centre), 1.0) if vig_ok else math.nan

    # bright featureless 8x8 tiles (droplets, glare)
    th, tw = yh.shape[0] // 8, yh.shape[1] // 8
    crop = yh[:th * 8, :tw * 8]
    tmean = cv2.resize(crop, (tw, th), interpolation=cv2.INTER_AREA)
    tsq = cv2.resize(cv2.multiply(crop, crop), (tw, th), interpolation=cv2.INTER_AREA)
    tvar = tsq - tmean * tmean
    bright = (tmean > 170.0) & (tvar < 16.0)
    if sm is None:
        out["bright_flat"] = float(bright.mean())
    else:
        n_tiles = int(np.count_nonzero(sm.tiles))
        out["bright_flat"] = float(np.count_nonzero(bright & sm.tiles)) / n_tiles if n_tiles else math.nan

    out["cone_contrast"], out["cone_sharp"] = _cones(y, image, boxes, None if sm is None else sm.ignored)
    return np.array([out[n] for n in SIGNAL_NAMES], dtype=np.float64)


def signal_table(images: Sequence[np.ndarray], depths: Sequence[np.ndarray | None] | None = None,
                 boxes: Sequence[np.ndarray | None] | None = None,
                 masks: Sequence[np.ndarray | SignalMask | None] | None = None) -> np.ndarray:
    """``(N, S)`` signals of ``N`` frames (depths, boxes and ignore masks per frame, or None)."""
    n = len(images)
    out = np.empty((n, len(SIGNALS)), np.float64)
    prepared: dict[int, SignalMask | None] = {}
    for i in range(n):
        m = None if masks is None else masks[i]
        if m is not None and not isinstance(m, SignalMask):
            if id(m) not in prepared:
                prepared[id(m)] = signal_mask(m)
            m = prepared[id(m)]
        out[i] = frame_signals(images[i], None if depths is None else depths[i],
                               None if boxes is None else boxes[i], m)
    return out
