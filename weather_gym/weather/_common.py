"""Small helpers shared by the effects: sRGB transfer curve, sensor noise, blends, blur, camera geometry.

Everything returned from a cache is read-only.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather._common import srgb_decode, srgb_encode
    >>> bool(np.allclose(srgb_encode(srgb_decode(np.arange(256) / 255)), np.arange(256) / 255))
    True
"""

from __future__ import annotations

import math
import threading
from functools import lru_cache
from statistics import NormalDist

import cv2
import numpy as np

from weather_gym.core.errors import InputError

#: Horizontal field of view assumed when neither the state nor the effect gives a focal length.
DEFAULT_HFOV_DEG = 90.0


def readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def flat(img: np.ndarray) -> np.ndarray:
    """View a C-contiguous ``(..., W, 3)`` uint8 image as 2-D ``(rows, W*3)`` (fast single-channel cv2)."""
    return img.reshape(-1, img.shape[-2] * img.shape[-1])


def srgb_decode(v: np.ndarray) -> np.ndarray:
    """sRGB encoded value in [0, 1] -> linear light in [0, 1] (IEC 61966-2-1)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] -> sRGB encoded value in [0, 1] (clipped)."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_slope(x: np.ndarray) -> np.ndarray:
    """d(encoded)/d(linear) at linear value ``x``."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92, 1.055 / 2.4 * np.power(np.maximum(x, 1e-12), 1 / 2.4 - 1))


@lru_cache(maxsize=1)
def linear_of_code() -> np.ndarray:
    """Linear light of each 8-bit code value (256,)."""
    return readonly(srgb_decode(np.arange(256) / 255.0))


@lru_cache(maxsize=1)
def gauss_lut() -> np.ndarray:
    """256 equiprobable standard-normal quantiles (unit variance), float32.

    Mapping a uniform random byte through this table gives a standard normal quantised to 256
    levels (truncated at +-2.9 sigma), over 10x cheaper than ``Generator.standard_normal``.
    """
    q = np.array([NormalDist().inv_cdf((i + 0.5) / 256.0) for i in range(256)])
    q /= q.std()
    return readonly(q.astype(np.float32))


# -- sensor noise ------------------------------------------------------------------------------
#
# Per pixel and channel the noise is ``s * round(sigma[I] * |z|)``: ``s`` a fresh random sign
# (one random bit per value and frame, from the generator), ``|z|`` a half-normal magnitude read
# from a fixed table of 2**20-entry chunks of equiprobable quantiles (the "bank", the same in
# every process, like :func:`gauss_lut`) through a window the generator places anew every frame
# (random offset and random row pitch). Within a frame the values are independent; across frames
# every value gets a fresh sign, so the noise of two frames is uncorrelated at every shift, and
# a pixel's magnitude comes from an unrelated place of the table. The arithmetic is that of uint8
# OpenCV passes (sigma look-up, multiply, subtract, masked add), done as one compiled pass with one
# table look-up per value (:mod:`~weather_gym.weather._noise_pass`), far cheaper than
# ``standard_normal`` per value.

_BANK_SEED = 20220607
_BANK_CHUNK = 1 << 20
#: The bank grows to what the frame size needs, at most this many entries (then windows overlap more).
_BANK_MAX = 1 << 25
_bank = readonly(np.empty(0, np.uint8))
_bank_lock = threading.Lock()


@lru_cache(maxsize=1)
def _half_normal_u8() -> tuple[np.ndarray, float]:
    """``(table, scale)``: byte -> |z| in 1/64 (the 128 positive quantiles of :func:`gauss_lut`),
    and the factor that makes those levels' mean square exactly 1."""
    levels = np.rint(gauss_lut()[128:].astype(np.float64) * 64.0)
    table = np.tile(levels, 2).astype(np.uint8)  # the byte's top bit is ignored
    return readonly(table), float(1.0 / np.sqrt(np.mean(levels ** 2)))


def noise_bank(size: int) -> np.ndarray:
    """The first ``size`` (or more) entries of the process-wide |z| table (uint8, read-only)."""
    global _bank
    bank = _bank
    if bank.size >= size:
        return bank
    with _bank_lock:
        bank = _bank
        if bank.size < size:
            table, _ = _half_normal_u8()
            parts = [bank]
            for i in range(bank.size // _BANK_CHUNK, -(-size // _BANK_CHUNK)):
                raw = np.random.default_rng([_BANK_SEED, i]).bit_generator.random_raw(_BANK_CHUNK // 8)
                parts.append(cv2.LUT(raw.view(np.uint8).reshape(256, -1), table).ravel())
            bank = readonly(np.concatenate(parts))
            _bank = bank
    return bank


@lru_cache(maxsize=32)
def _bank_plan(rows: int, cols: int) -> tuple[int, int, int]:
    """``(bank size, offset range, extra row pitch range)`` of the per-frame windows of a frame size."""
    n = rows * cols
    extra = max(min(2 * n, _BANK_MAX - n), 1 << 16)
    offsets = max(extra // 2, 1)
    pitches = max(min(cols, (extra // 2) // max(rows - 1, 1)), 1)
    return offsets + (rows - 1) * (cols + pitches - 1) + cols, offsets, pitches


@lru_cache(maxsize=64)
def noise_table(mean_bytes: bytes | None, sigma_bytes: bytes) -> np.ndarray:
    """The noisy value for every sign, value and magnitude: uint8, ``table[sign << 16 | v << 8 | m]``.

    ``mean[v] - a`` (sign 0) or ``mean[v] + a`` (sign 1), saturated to 0-255, with
    ``a = min(round(float32(float32(s) * u[v]) * m), 255)`` (rounding half to even): ``u`` the sigma
    table in units of 1/255 of its largest value (at most 4000), ``m`` a magnitude of
    :func:`noise_bank` in 1/64, ``s`` the two scales together; ``mean_bytes`` None means the
    identity. This is ``cv2.multiply(u[v], m, scale=s)`` then a saturating subtract or add, the
    arithmetic the noise had as OpenCV passes.
    """
    sigma = np.minimum(np.frombuffer(sigma_bytes, np.float32).astype(np.float64), 4000.0)
    top = float(sigma.max())
    unit = top / 255.0 if top > 0 else 1.0
    units = np.clip(np.rint(sigma / unit), 0, 255).astype(np.float32)
    if mean_bytes is None:
        mean = np.arange(256, dtype=np.int16)
    else:
        mean = np.clip(np.rint(np.frombuffer(mean_bytes, np.float32)), 0, 255).astype(np.int16)
    scale = np.float32(unit * _half_normal_u8()[1])
    a = np.minimum(np.rint((scale * units)[:, None] * np.arange(256, dtype=np.float32)), 255).astype(np.int16)
    table = np.stack([mean[:, None] - a, mean[:, None] + a])
    return readonly(np.clip(table, 0, 255).astype(np.uint8).ravel())


def _noise_words(shape: tuple[int, ...]) -> tuple[int, int]:
    """``(frames, 64-bit words per frame)`` of the sensor-noise draw of an image or batch ``shape``."""
    frames = 1 if len(shape) == 3 else int(shape[0])
    n = int(shape[-3]) * int(shape[-2]) * int(shape[-1])
    return frames, 2 + (n + 63) // 64


def sensor_noise_draw(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """The random words :func:`add_sensor_noise` needs for a frame or batch of ``shape``:
    ``(frames, words)`` uint64, a window offset and pitch then one sign bit per value, per frame."""
    frames, per = _noise_words(shape)
    return rng.bit_generator.random_raw(frames * per).reshape(frames, per)


def add_sensor_noise(img: np.ndarray, mean_lut: np.ndarray | None, sigma_lut: np.ndarray,
                     raw: np.ndarray | np.random.Generator, out: np.ndarray | None = None) -> np.ndarray:
    """``mean_lut[I] + round(sigma_lut[I] * z)``, clipped to 0-255, ``z`` standard normal per value.

    ``mean_lut`` None means the identity. ``img`` is a uint8 ``H x W x 3`` frame or an
    ``N x H x W x 3`` batch (the same noise as frame-by-frame calls); the result goes to ``out``
    (new when None). ``z`` is a fresh random sign times a magnitude from :func:`noise_bank` (see
    the comment above), 256 equiprobable levels as :func:`gauss_lut`; sigma is resolved to 1/255
    of its largest value in the table. ``raw``: the random words, :func:`sensor_noise_draw` (or a
    generator to draw them from).
    """
    if isinstance(raw, np.random.Generator):
        raw = sensor_noise_draw(raw, img.shape)
    from weather_gym.weather._noise_pass import noise_pass  # numba loads with the first noisy frame

    table = noise_table(None if mean_lut is None else np.asarray(mean_lut, np.float32).tobytes(),
                        np.asarray(sigma_lut, np.float32).tobytes())
    if out is None:
        out = np.empty_like(img)
    target = out if out.flags.c_contiguous else np.empty_like(img)
    frames = img.reshape(-1, img.shape[-3], img.shape[-2] * img.shape[-1])
    n_frames, rows, cols = frames.shape
    size, offsets, pitches = _bank_plan(rows, cols)
    raw = np.ascontiguousarray(np.asarray(raw).reshape(n_frames, -1))
    picks = raw[:, :2].tolist()
    noise_pass(frames, target.reshape(frames.shape), table, noise_bank(size),
               np.array([p[0] % offsets for p in picks], np.int64),
               np.array([cols + p[1] % pitches for p in picks], np.int64), raw[:, 2:].view(np.uint8))
    return into(target, out)


def into(res: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out`` holding ``res``: OpenCV writes into a ``dst`` it can use, else returns a new array."""
    if res is not out and not np.may_share_memory(res, out):
        np.copyto(out, res)
    return out


def focal_px(state: dict[str, float], width: int, hfov_deg: float) -> float:
    """Focal length in pixels: ``state['fx']`` when given, else from the horizontal field of view."""
    if "fx" in state:
        return state["fx"]
    return 0.5 * width / math.tan(math.radians(hfov_deg) / 2)


@lru_cache(maxsize=16)
def ray_factor(h: int, w: int, fx: float) -> np.ndarray:
    """Range / z-depth of each pixel for a pinhole camera with square pixels, principal point at centre."""
    u = (np.arange(w, dtype=np.float32) - (w - 1) / 2) / fx
    v = (np.arange(h, dtype=np.float32) - (h - 1) / 2) / fx
    return readonly(np.sqrt(1.0 + u[None, :] ** 2 + v[:, None] ** 2).astype(np.float32))


@lru_cache(maxsize=16)
def ground_depth(h: int, w: int, fx: float, camera_height_m: float, horizon_frac: float,
                 far_m: float) -> np.ndarray:
    """Fallback z-depth when none is given: a flat ground plane seen by a level camera.

    A row ``v`` pixels below the horizon row (``horizon_frac * H``) sees the ground at
    ``z = fx * camera_height / v``; rows at or above the horizon (sky, far background) get ``far_m``.
    """
    v = np.arange(h, dtype=np.float64) + 0.5 - horizon_frac * h
    z = np.full(h, far_m)
    below = v > 0
    z[below] = np.minimum(fx * camera_height_m / v[below], far_m)
    return readonly(np.repeat(z.astype(np.float32)[:, None], w, axis=1))


def scene_depth(depth: np.ndarray | None, h: int, w: int, fx: float, camera_height_m: float,
                horizon_frac: float, far_m: float, who: str) -> np.ndarray:
    """The given depth map (validated finite, >= 0) or the flat-ground fallback."""
    if depth is None:
        return ground_depth(h, w, fx, camera_height_m, horizon_frac, far_m)
    depth_min(depth, who)
    return depth


def depth_min(depth: np.ndarray, who: str) -> float:
    """The smallest depth, after checking that all are finite metres >= 0 (two reductions)."""
    lo, hi = float(depth.min()), float(depth.max())  # NaN fails both tests
    if not (lo >= 0 and hi < math.inf):
        raise InputError(f"{who}: depth must be finite metres >= 0 (got NaN, inf or negative values)")
    return lo


def blend_terms(w1: np.ndarray, target: float | tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The two halves of a blend towards a constant: ``(255 - w, target * w / 255)`` as uint8 RGB.

    ``w1``: uint8 single-channel weights (255 = all target); ``target``: a gray level or an RGB
    colour (0-255). With :func:`blend_into` this is ``img + (target - img) * w / 255``.
    """
    inv3 = cv2.cvtColor(cv2.bitwise_not(w1), cv2.COLOR_GRAY2RGB)
    if isinstance(target, tuple):
        add3 = cv2.merge([cv2.convertScaleAbs(w1, alpha=c / 255.0) for c in target])
    else:
        add3 = cv2.cvtColor(cv2.convertScaleAbs(w1, alpha=target / 255.0), cv2.COLOR_GRAY2RGB)
    return inv3, add3


def blend_into(img: np.ndarray, terms: tuple[np.ndarray, np.ndarray], out: np.ndarray) -> np.ndarray:
    """``out = img * (255 - w) / 255 + target * w / 255`` from :func:`blend_terms` (two OpenCV passes)."""
    inv3, add3 = terms
    return into(cv2.add(cv2.multiply(img, inv3, scale=1 / 255), add3, dst=out), out)


#: Variance (px^2) of one pass of OpenCV's 3x3 and 5x5 box filters, its only fast ones here: other
#: sizes, and ``GaussianBlur``, take 3 to 8 times longer on a 672x376 frame.
_BOX_VAR = {3: 8 / 12, 5: 24 / 12}
#: Variance the 2x area reduction and the linear enlargement back add (px^2 at full resolution).
_RESAMPLE_VAR = 1.0


def _box_passes(var: float, exact: bool = False) -> tuple[list[int], float]:
    """Box sizes whose variances add up to ``var`` within 10 % (fewest passes), else (or always with
    ``exact``) those just below and the fraction of one more 3x3 pass to blend in for the rest."""
    if exact:
        f = int(var // _BOX_VAR[5])
        t = int((var - f * _BOX_VAR[5]) // _BOX_VAR[3])
        return [5] * f + [3] * t, (var - f * _BOX_VAR[5] - t * _BOX_VAR[3]) / _BOX_VAR[3]
    combos = [(f, t) for f in range(4) for t in range(4) if f + t]
    f, t = min(combos, key=lambda c: (abs(c[0] * _BOX_VAR[5] + c[1] * _BOX_VAR[3] - var) > 0.1 * var,
                                      sum(c), abs(c[0] * _BOX_VAR[5] + c[1] * _BOX_VAR[3] - var)))
    if abs(f * _BOX_VAR[5] + t * _BOX_VAR[3] - var) <= 0.1 * var:
        return [5] * f + [3] * t, 0.0
    f = int(var // _BOX_VAR[5])
    t = int((var - f * _BOX_VAR[5]) // _BOX_VAR[3])
    return [5] * f + [3] * t, (var - f * _BOX_VAR[5] - t * _BOX_VAR[3]) / _BOX_VAR[3]


def smooth(img: np.ndarray, sigma: float, out: np.ndarray | None = None, *, exact: bool = False) -> np.ndarray:
    """Gaussian-like blur of standard deviation ``sigma`` px, into ``out`` (new when None).

    The variance ``sigma**2`` is made of OpenCV's fast 5x5 and 3x3 box passes (a box pass is
    ``(n^2 - 1) / 12`` px^2 per axis), the remainder a fraction of one more 3x3 pass blended in;
    above ``sigma = 2.5`` the frame is halved first (area average) and enlarged back (linear),
    which adds about 1 px^2 itself. Border: reflected. Without ``exact``, a combination of passes
    within 10 % of the variance is used as it is (fewest passes); with it the result changes
    continuously with ``sigma`` (what fitting a blur needs). ``out`` may be ``img`` (smoothed in place).
    """
    if out is None:
        out = np.empty_like(img)
    if sigma < 0.3:
        np.copyto(out, img)
        return out
    h, w = img.shape[:2]
    var = sigma * sigma
    if sigma > 2.5 and min(h, w) >= 8:
        small = cv2.resize(img, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        small = smooth(small, math.sqrt(var - _RESAMPLE_VAR) / 2, exact=exact)
        return into(cv2.resize(small, (w, h), dst=out, interpolation=cv2.INTER_LINEAR), out)
    sizes, frac = _box_passes(var, exact)
    src = img
    for i, n in enumerate(sizes):
        last = i == len(sizes) - 1 and not frac
        dst = out if last else None
        src = cv2.blur(src, (n, n), dst=dst, borderType=cv2.BORDER_REFLECT)
    if frac:
        more = cv2.blur(src, (3, 3), borderType=cv2.BORDER_REFLECT)
        src = cv2.addWeighted(more, frac, src, 1.0 - frac, 0, dst=out)
    return into(src, out)
