"""Measured members of the effect families: the non-parametric fall-back when a parametric effect falls short.

When no parametric effect of a kind reproduces the measured frames (its range clips the fit, or it
leaves most of the gap), the gap workflow measures the effect itself, from the fitting frames, as a
member of the same kind, named by that kind:

* ``tone_curve`` (exposure / tone): a monotone tone curve per channel, ``KNOTS`` output values at
  equally spaced inputs (quantile matching of the model's frames to the measured ones);
* ``noise_level`` (sensor noise): a noise-level function, the sigma (code values) of the noise to
  add per channel as a function of the value, at ``KNOTS`` equally spaced values (the measured noise
  variance minus the model's, per intensity bin);
* ``radial_gain`` (vignette): a smooth gain on the code values against the distance from the centre
  (0 at the centre, 1 at the corners), at ``KNOTS`` equally spaced radii;
* ``blur_kernel`` (blur / motion blur): a measured point-spread function, a square kernel stored row
  by row (paired frames: the Wiener estimate of the kernel that maps the model's frames to the
  measured ones; unpaired: the zero-phase kernel of the ratio of their power spectra).

Each is a :class:`~weather_gym.weather.base.KnobEffect` whose curve is a tuple of floats; ``k``
blends from no change (0) to the measured curve (1). A model file holds them like any effect
(arrays of numbers)::

    [[effects]]
    name = "tone_curve"
    k = 1.0
    r = [0.0, 0.01, ...]
    g = [0.0, 0.01, ...]
    b = [0.0, 0.01, ...]

They are not registered as weather effects (the weather registry's effects have scalar parameters):
:data:`MEASURED` is their registry, and :func:`~weather_gym.lab.gap.weather_model.read_model` reads both. The
curves are measured at the comparison size of the gap run (noise at another resolution differs).

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.gap.measured import make_measured
    >>> e = make_measured("tone_curve", k=1.0, r=[0.0, 0.25, 1.0], g=[0.0, 0.25, 1.0], b=[0.0, 0.25, 1.0])
    >>> int(e(np.full((2, 2, 3), 128, np.uint8))[0, 0, 0])
    64
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import cv2
import numpy as np
from pydantic import BeforeValidator

from weather_gym.core.errors import InputError, check_known
from weather_gym.core.registry import Registry
from weather_gym.weather.base import KnobEffect

__all__ = ["MEASURED", "KIND", "PARTNERS", "MEASURED_PARAMS", "KNOTS", "MeasuredEffect", "ToneCurve", "NoiseLevel",
           "RadialGain", "BlurKernel", "make_measured", "estimate", "shape_text"]

KNOTS = 17
"""Knots of a measured curve (inputs 0, 1/16, ..., 1)."""

MEASURED_PARAMS = 4
"""A measured member is penalised as this many parameters (a parametric effect of the kind wins when close)."""

MEASURED: Registry[type[MeasuredEffect]] = Registry("measured effect")

#: measured member -> the kind it is named by (the family of image signals it answers)
KIND: dict[str, str] = {"tone_curve": "tone", "noise_level": "noise", "radial_gain": "vignette",
                        "blur_kernel": "sharpness"}
#: measured member -> the parametric effects of the same kind (where it goes in the chain: after them)
PARTNERS: dict[str, tuple[str, ...]] = {"tone_curve": ("exposure",), "noise_level": ("noise",),
                                        "radial_gain": ("vignette",), "blur_kernel": ("blur", "motion_blur")}


def _curve(who: str, field: str, v: Any, lo: float, hi: float, monotone: bool) -> tuple[float, ...]:
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{who}: parameter {field} must be an array of numbers, got {v!r}") from None
    if arr.ndim != 1 or not 1 <= arr.size <= 1024:
        raise InputError(f"{who}: parameter {field} must be an array of 1 to 1024 numbers, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or arr.min() < lo or arr.max() > hi:
        raise InputError(f"{who}: parameter {field} values must be finite and in [{lo}, {hi}]")
    if monotone and np.any(np.diff(arr) < -1e-9):
        raise InputError(f"{who}: parameter {field} must be non-decreasing (a monotone tone curve)")
    return tuple(round(float(x), 4) for x in arr)


@dataclass(frozen=True)
class MeasuredEffect(KnobEffect):
    """Base of the measured members: ``k`` in [0, 1] plus curve fields (tuples of floats)."""

    CURVES: ClassVar[dict[str, tuple[float, float, bool]]] = {}  # field -> (lo, hi, monotone)
    MEASURED: ClassVar[bool] = True

    @classmethod
    def param_type(cls, param: str, annotation: Any) -> Any:
        """A curve field: a tuple of floats in its range (and monotone where declared), rounded."""
        if param in cls.CURVES:
            lo, hi, mono = cls.CURVES[param]
            who = cls.name or cls.__name__
            return Annotated[tuple[float, ...], BeforeValidator(lambda v: _curve(who, param, v, lo, hi, mono))]
        return super().param_type(param, annotation)

    def params(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def is_identity(self, tol: float = 0.002) -> bool:
        """Whether the measured curves change (next to) nothing."""
        return all(np.allclose(getattr(self, f), getattr(type(self), f), atol=tol * hi)
                   for f, (lo, hi, _) in self.CURVES.items())

    def summary(self) -> str:
        """``name(k=..., measured: <shape>)``: short, for logs and reports."""
        return f"{self.name}(k={self.k:.4g}, measured: {shape_text(self)})"


def _interp(knots: Sequence[float], x: np.ndarray) -> np.ndarray:
    return np.interp(x, np.linspace(0.0, 1.0, len(knots)), np.asarray(knots, np.float64))


_IDENTITY = tuple(float(x) for x in np.linspace(0.0, 1.0, KNOTS))
_ZEROS = (0.0,) * KNOTS
_ONES = (1.0,) * KNOTS


@MEASURED.register("tone_curve")
@dataclass(frozen=True)
class ToneCurve(MeasuredEffect):
    """A measured monotone tone curve per channel (outputs in [0, 1] at equally spaced inputs)."""

    name: ClassVar[str] = "tone_curve"
    r: tuple[float, ...] = _IDENTITY
    g: tuple[float, ...] = _IDENTITY
    b: tuple[float, ...] = _IDENTITY
    CURVES: ClassVar = {"r": (0.0, 1.0, True), "g": (0.0, 1.0, True), "b": (0.0, 1.0, True)}

    def lut(self) -> np.ndarray:
        x = np.arange(256) / 255.0
        cols = [(1 - self.k) * x + self.k * _interp(c, x) for c in (self.r, self.g, self.b)]
        return np.clip(np.rint(255.0 * np.stack(cols, 1)), 0, 255).astype(np.uint8).reshape(256, 1, 3)

    def _apply_into(self, img, depth, state, rng, out):
        np.copyto(out, cv2.LUT(img, self.lut()))


@MEASURED.register("noise_level")
@dataclass(frozen=True)
class NoiseLevel(MeasuredEffect):
    """A measured noise-level function per channel: sigma (code values) at equally spaced values."""

    name: ClassVar[str] = "noise_level"
    r: tuple[float, ...] = _ZEROS
    g: tuple[float, ...] = _ZEROS
    b: tuple[float, ...] = _ZEROS
    CURVES: ClassVar = {"r": (0.0, 128.0, False), "g": (0.0, 128.0, False), "b": (0.0, 128.0, False)}

    def _apply_into(self, img, depth, state, rng, out):
        x = np.arange(256) / 255.0
        z = rng.standard_normal(img.shape, dtype=np.float32)
        res = img.astype(np.float32)
        for c, knots in enumerate((self.r, self.g, self.b)):
            sigma = (self.k * _interp(knots, x)).astype(np.float32)
            res[..., c] += sigma[img[..., c]] * z[..., c]
        np.copyto(out, np.clip(np.rint(res), 0, 255).astype(np.uint8))


@MEASURED.register("radial_gain")
@dataclass(frozen=True)
class RadialGain(MeasuredEffect):
    """A measured gain on the code values against the distance from the centre (1 = the corners)."""

    name: ClassVar[str] = "radial_gain"
    gain: tuple[float, ...] = _ONES
    CURVES: ClassVar = {"gain": (0.0, 4.0, False)}

    def gain_map(self, h: int, w: int) -> np.ndarray:
        g = 1.0 + self.k * (_interp(self.gain, _radius(h, w)) - 1.0)
        return g.astype(np.float32)

    def _apply_into(self, img, depth, state, rng, out):
        g = self.gain_map(*img.shape[:2])
        np.copyto(out, np.clip(np.rint(img.astype(np.float32) * g[..., None]), 0, 255).astype(np.uint8))


@MEASURED.register("blur_kernel")
@dataclass(frozen=True)
class BlurKernel(MeasuredEffect):
    """A measured blur kernel (point-spread function): an odd square, row by row, summing to 1."""

    name: ClassVar[str] = "blur_kernel"
    kernel: tuple[float, ...] = (1.0,)
    CURVES: ClassVar = {"kernel": (0.0, 1.0, False)}

    def __post_init__(self) -> None:
        super().__post_init__()  # the declared parameters first
        n = math.isqrt(len(self.kernel))
        if n * n != len(self.kernel) or n % 2 == 0 or abs(sum(self.kernel) - 1.0) > 0.01:
            raise InputError(f"{self.name}: parameter kernel must hold an odd square of weights (row by row) that "
                             f"sum to 1, got {len(self.kernel)} weights summing to {sum(self.kernel):.4g}")

    @property
    def side(self) -> int:
        return math.isqrt(len(self.kernel))

    def matrix(self) -> np.ndarray:
        n = self.side
        k = self.k * np.asarray(self.kernel, np.float32).reshape(n, n)
        k[n // 2, n // 2] += 1.0 - self.k
        return k

    def _apply_into(self, img, depth, state, rng, out):
        np.copyto(out, cv2.filter2D(img, -1, self.matrix(), borderType=cv2.BORDER_REFLECT))

    def is_identity(self, tol: float = 0.002) -> bool:
        k = np.asarray(self.kernel)
        return bool(k[len(k) // 2] >= 1.0 - tol)


def make_measured(name: str, **params: Any) -> MeasuredEffect:
    """Build the measured effect ``name`` (errors list the valid names and say what is expected)."""
    cls = MEASURED.get(name)
    check_known(params, [f.name for f in dataclasses.fields(cls)], what=name, kind="parameter")
    return cls(**params)


def _radius(h: int, w: int) -> np.ndarray:
    y = (np.arange(h) + 0.5 - h / 2.0)[:, None]
    x = (np.arange(w) + 0.5 - w / 2.0)[None, :]
    return np.minimum(np.hypot(x, y) / (0.5 * math.hypot(w, h)), 1.0)


def _keep(masks: Sequence[np.ndarray | None] | None, i: int, shape: tuple[int, int]) -> np.ndarray:
    m = None if masks is None else masks[i]
    return np.ones(shape, bool) if m is None else ~np.asarray(m, bool)


def _tone(sim: Sequence[np.ndarray], meas: Sequence[np.ndarray], sim_masks, meas_masks) -> ToneCurve:
    curves = {}
    x = np.linspace(0.0, 255.0, KNOTS)
    for c, key in enumerate("rgb"):
        hs = sum(np.bincount(im[..., c][_keep(sim_masks, i, im.shape[:2])], minlength=256)  # type: ignore[union-attr]  # frames: never empty
                 for i, im in enumerate(sim)).astype(np.float64)
        hm = sum(np.bincount(im[..., c][_keep(meas_masks, i, im.shape[:2])], minlength=256)  # type: ignore[union-attr]  # frames: never empty
                 for i, im in enumerate(meas)).astype(np.float64)
        cs = (np.cumsum(hs) - 0.5 * hs) / max(hs.sum(), 1.0)
        cm = (np.cumsum(hm) - 0.5 * hm) / max(hm.sum(), 1.0)
        lut = np.interp(cs, cm, np.arange(256.0))  # the measured value at the same rank
        lut[hs == 0] = np.nan
        ok = np.isfinite(lut)
        lut = np.interp(np.arange(256.0), np.flatnonzero(ok), lut[ok]) if ok.any() else np.arange(256.0)
        knots = np.maximum.accumulate(np.clip(np.interp(x, np.arange(256.0), lut) / 255.0, 0.0, 1.0))
        curves[key] = knots
    return ToneCurve(k=1.0, **curves)  # type: ignore[arg-type]  # the checked constructor makes tuples of the arrays


_IMMERKAER = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32) / 6.0


def _noise_profile(frames: Sequence[np.ndarray], masks) -> np.ndarray:
    """Robust noise sigma per channel and value bin (``KNOTS`` bins), NaN where too few pixels."""
    edges = np.linspace(0.0, 256.0, KNOTS + 1)
    out = np.full((3, KNOTS), np.nan)
    for c in range(3):
        res, lev = [], []
        for i, im in enumerate(frames):
            ch = im[..., c].astype(np.float32)
            r = cv2.filter2D(ch, -1, _IMMERKAER, borderType=cv2.BORDER_REFLECT)[1:-1, 1:-1]
            m = cv2.blur(ch, (3, 3))[1:-1, 1:-1]
            keep = _keep(masks, i, im.shape[:2])[1:-1, 1:-1]
            res.append(np.abs(r[keep]))
            lev.append(m[keep])
        res_a, lev_a = np.concatenate(res), np.concatenate(lev)
        idx = np.clip(np.digitize(lev_a, edges) - 1, 0, KNOTS - 1)
        for b in range(KNOTS):
            sel = res_a[idx == b]
            if sel.size >= 200:
                out[c, b] = 1.4826 * float(np.median(sel))
    return out


def _noise(sim, meas, sim_masks, meas_masks) -> NoiseLevel:
    ps, pm = _noise_profile(sim, sim_masks), _noise_profile(meas, meas_masks)
    var = pm ** 2 - ps ** 2
    curves = {}
    for c, key in enumerate("rgb"):
        v = var[c]
        ok = np.isfinite(v)
        s = np.sqrt(np.maximum(np.interp(np.arange(KNOTS), np.flatnonzero(ok), v[ok]), 0.0)) if ok.any() else (
            np.zeros(KNOTS))
        curves[key] = np.clip(s, 0.0, 128.0)
    return NoiseLevel(k=1.0, **curves)  # type: ignore[arg-type]  # the checked constructor makes tuples of the arrays


def _radial(sim, meas, sim_masks, meas_masks, paired: bool) -> RadialGain:
    h, w = sim[0].shape[:2]
    rb = np.clip(np.rint(_radius(h, w) * (KNOTS - 1)).astype(int), 0, KNOTS - 1)
    num, den = np.zeros(KNOTS), np.zeros(KNOTS)
    for i in range(len(sim) if paired else 0):
        ys, ym = sim[i].mean(2), meas[i].mean(2)
        keep = _keep(sim_masks, i, (h, w)) & _keep(meas_masks, i, (h, w)) & (ys > 8) & (ys < 247)
        num += np.bincount(rb[keep], ym[keep], KNOTS)
        den += np.bincount(rb[keep], ys[keep], KNOTS)
    if not paired:  # other views: the mean luma per radius, averaged over each set's frames
        for frames, masks, acc in ((meas, meas_masks, num), (sim, sim_masks, den)):
            for i, im in enumerate(frames):
                keep = _keep(masks, i, (h, w))
                n = np.bincount(rb[keep], minlength=KNOTS)
                acc += np.where(n > 0, np.bincount(rb[keep], im.mean(2)[keep], KNOTS) / np.maximum(n, 1), 0.0) / len(frames)
    g = np.where(den > 0, num / np.maximum(den, 1e-9), np.nan)
    ok = np.isfinite(g)
    g = np.interp(np.arange(KNOTS), np.flatnonzero(ok), g[ok]) if ok.any() else np.ones(KNOTS)
    g = np.convolve(np.pad(g, 1, mode="edge"), [0.25, 0.5, 0.25], mode="valid")  # smooth
    return RadialGain(k=1.0, gain=np.clip(g, 0.0, 4.0))


def _luma(im: np.ndarray) -> np.ndarray:
    return im.astype(np.float64) @ np.array([0.299, 0.587, 0.114])


def _kernel(sim, meas, paired: bool, radius: int) -> BlurKernel:
    h, w = sim[0].shape[:2]
    win = np.outer(np.hanning(h), np.hanning(w))
    num = np.zeros((h, w), complex)
    den = np.zeros((h, w))
    pm = np.zeros((h, w))
    for i in range(len(sim) if paired else 0):
        fs, fm = np.fft.fft2((_luma(sim[i]) - _luma(sim[i]).mean()) * win), np.fft.fft2(
            (_luma(meas[i]) - _luma(meas[i]).mean()) * win)
        num += fm * np.conj(fs)
        den += np.abs(fs) ** 2
    if paired:
        kf = num / (den + 1e-3 * den.mean())
    else:  # other views: only the magnitude of the transfer function, from the power spectra
        for frames, acc in ((sim, den), (meas, pm)):
            for im in frames:
                acc += np.abs(np.fft.fft2((_luma(im) - _luma(im).mean()) * win)) ** 2 / len(frames)
        kf = np.sqrt(np.minimum(pm / np.maximum(den, 1e-12), 1.0))
    k = np.fft.fftshift(np.real(np.fft.ifft2(kf)))
    cy, cx = h // 2, w // 2
    k = np.clip(k[cy - radius:cy + radius + 1, cx - radius:cx + radius + 1], 0.0, None)
    if k.sum() > 0:
        k = k / k.sum()
    else:  # nothing measurable: no blur
        k[radius, radius] = 1.0
    k = np.round(k, 4)
    k[radius, radius] += 1.0 - k.sum()  # exactly 1 after rounding
    return BlurKernel(k=1.0, kernel=np.clip(k, 0.0, 1.0).ravel())  # type: ignore[arg-type]  # made a tuple by the checked constructor


def estimate(name: str, sim: Sequence[np.ndarray], meas: Sequence[np.ndarray], *,
             sim_masks: Sequence[np.ndarray | None] | None = None,
             meas_masks: Sequence[np.ndarray | None] | None = None, paired: bool = False) -> MeasuredEffect:
    """Measure member ``name`` so that ``sim`` frames (the current model's output) look like ``meas``.

    ``paired``: ``sim[i]`` shows the view of ``meas[i]`` (the radial gain then uses per-pixel
    ratios; the tone curve and noise level compare distributions either way).
    """
    if name == "tone_curve":
        return _tone(sim, meas, sim_masks, meas_masks)
    if name == "noise_level":
        return _noise(sim, meas, sim_masks, meas_masks)
    if name == "radial_gain":
        return _radial(sim, meas, sim_masks, meas_masks, paired)
    if name == "blur_kernel":
        return _kernel(sim, meas, paired, radius=max(2, min(15, int(round(0.02 * sim[0].shape[1])))))
    raise InputError(f"unknown measured effect {name!r}; valid names: {', '.join(MEASURED.names())}")


def shape_text(e: MeasuredEffect) -> str:
    """The residual shape a measured member found, in words (what no parametric effect reproduced)."""
    if isinstance(e, ToneCurve):
        q = [0.25, 0.5, 0.75]
        mean = np.mean([_interp(c, np.array(q)) for c in (e.r, e.g, e.b)], axis=0)
        spread = max(float(np.max(np.abs(_interp(a, np.array(q)) - _interp(bb, np.array(q)))))
                     for a, bb in ((e.r, e.g), (e.g, e.b), (e.r, e.b)))
        return (f"tone curve maps 25/50/75 % to {mean[0]:.0%}/{mean[1]:.0%}/{mean[2]:.0%}"
                + (f", channels differ by up to {spread:.0%}" if spread > 0.03 else ""))
    if isinstance(e, NoiseLevel):
        s = np.mean([c for c in (e.r, e.g, e.b)], axis=0)
        n = len(s)
        return (f"added noise sigma {s[n // 8]:.1f} / {s[n // 2]:.1f} / {s[7 * n // 8]:.1f} codes in "
                "dark / mid / bright values")
    if isinstance(e, BlurKernel):
        k = np.asarray(e.kernel).reshape(e.side, e.side)
        y, x = np.mgrid[0:e.side, 0:e.side] - e.side // 2
        sx, sy = math.sqrt(float((k * x * x).sum())), math.sqrt(float((k * y * y).sum()))
        return f"{e.side}x{e.side} kernel, spread {sx:.1f} px across and {sy:.1f} px up"
    if isinstance(e, RadialGain):
        g = np.asarray(e.gain)
        n = len(g)
        return f"gain {g[0]:.2f} at the centre, {g[n // 2]:.2f} half-way, {g[-1]:.2f} in the corners"
    return ""
