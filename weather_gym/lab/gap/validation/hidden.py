"""Hidden effects drawn from wide families, written independently of the weather library.

The gap workflow's promise is to name what is missing in someone else's data, so it is checked on
degradations it was never tuned to: each :class:`HiddenCase` is drawn by a seeded
``numpy.random.Generator`` from one of the :data:`FAMILIES` with parameters from wide ranges, and
applied with plain NumPy / OpenCV code of its own (nothing here imports ``weather_gym.weather``):

=========  ==================================================================================
family     what is drawn
=========  ==================================================================================
tone       a monotone curve through random knots (PCHIP), one for all channels or one per
           channel (a colour cast), black lift and white roll-off drawn too
noise      linear-light Poisson shot noise (full well 25-600 e-), Gaussian read noise (0.5-15 e-),
           fixed-pattern gain (PRNU) and offset (DSNU) noise fixed over the recording
blur       a Gaussian, box, disc or motion-line kernel, several sizes (a fraction of the width)
falloff    a radial fall-off: cos^4 of a lens of 30-60 deg half field, a polynomial 1 - a r^2 - b r^4,
           or a Gaussian; on linear light or on code values
jpeg       OpenCV's JPEG encoder at quality 4-35
haze       Koschmieder's law: airlight A (slightly tinted), transmission exp(-beta d) from the
           depth map (from the image rows where there is none)
pair       two of the above in the order a camera meets them (haze, falloff, blur, noise, tone, jpeg)
none       nothing hidden (the negative control)
=========  ==================================================================================

Example:
    >>> import numpy as np
    >>> case = draw_case("noise", seed=3)
    >>> img = np.full((48, 64, 3), 120, np.uint8)
    >>> out = case.apply(img, None, frame=0)
    >>> out.shape, case.family, bool(np.abs(out.astype(int) - 120).mean() > 0.5)
    ((48, 64, 3), 'noise', True)
    >>> np.array_equal(out, draw_case("noise", seed=3).apply(img, None, frame=0))
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from weather_gym.core.errors import InputError

__all__ = ["FAMILIES", "SINGLE", "ORDER", "ACCEPTED", "HiddenCase", "draw_case", "draw_params", "apply_family"]

#: single families, in the order a camera meets them (a composition applies its two in this order)
ORDER: tuple[str, ...] = ("haze", "falloff", "blur", "noise", "tone", "jpeg")
SINGLE: tuple[str, ...] = ("tone", "noise", "blur", "falloff", "jpeg", "haze")
FAMILIES: tuple[str, ...] = (*SINGLE, "pair", "none")
#: the names the workflow may give a family (parametric effects and measured members of its kind)
ACCEPTED: dict[str, tuple[str, ...]] = {
    "tone": ("exposure", "dim", "tone_curve"), "noise": ("noise", "noise_level"),
    "blur": ("blur", "motion_blur", "blur_kernel"), "falloff": ("vignette", "radial_gain"),
    "jpeg": ("jpeg",), "haze": ("fog",), "none": (),
}


def _lin(v: np.ndarray) -> np.ndarray:
    """sRGB code values (0-1) to linear light."""
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _enc(x: np.ndarray) -> np.ndarray:
    """Linear light to sRGB code values (0-1)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _u8(v: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(255.0 * v), 0, 255).astype(np.uint8)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _monotone_curve(rng: np.random.Generator, lift: float, top: float, n_knots: int) -> list[float]:
    """Outputs at 0, knots..., 1 of a monotone curve (increments drawn from a Dirichlet)."""
    inc = rng.dirichlet(np.full(n_knots + 1, 1.5))
    return (lift + (top - lift) * np.concatenate([[0.0], np.cumsum(inc)])).tolist()


def draw_params(family: str, rng: np.random.Generator) -> dict[str, Any]:
    """Parameters of one member of ``family`` (a single family), drawn from its wide ranges."""
    if family == "tone":
        n = int(rng.integers(2, 6))
        xs = np.sort(rng.uniform(0.08, 0.92, n))
        colour = bool(rng.random() < 0.4)
        lift, top = float(rng.uniform(0.0, 0.08)), float(rng.uniform(0.8, 1.0))
        while True:  # at least a visible change: mean |curve - identity| of 4 % of the range
            curves = [_monotone_curve(rng, lift, top, n) for _ in range(3 if colour else 1)]
            grid = np.linspace(0, 1, 65)
            dev = max(float(np.abs(np.interp(grid, [0.0, *xs, 1.0], c) - grid).mean()) for c in curves)
            if dev >= 0.04:
                break
        return {"knots": [0.0, *xs.tolist(), 1.0], "curves": curves, "colour": colour}
    if family == "noise":
        return {"full_well_e": _log_uniform(rng, 25.0, 600.0), "read_e": _log_uniform(rng, 0.5, 15.0),
                "prnu": float(rng.uniform(0.0, 0.03)), "dsnu": float(rng.uniform(0.0, 0.01)),
                "pattern_seed": int(rng.integers(2 ** 31))}
    if family == "blur":
        shape = str(rng.choice(["gaussian", "box", "disc", "motion"]))
        size = {"gaussian": rng.uniform(0.0025, 0.009), "box": rng.uniform(0.006, 0.022),
                "disc": rng.uniform(0.003, 0.011), "motion": rng.uniform(0.012, 0.045)}[shape]
        return {"shape": shape, "size_frac": float(size), "angle_deg": float(rng.uniform(0.0, 180.0))}
    if family == "falloff":
        law = str(rng.choice(["cos4", "poly", "gaussian"]))
        p: dict[str, Any] = {"law": law, "linear": bool(rng.random() < 0.5)}
        if law == "cos4":
            p["half_fov_deg"] = float(rng.uniform(30.0, 60.0))
        elif law == "poly":
            p["a"], p["b"] = float(rng.uniform(0.1, 0.45)), float(rng.uniform(0.0, 0.45))
        else:
            p["sigma"] = float(rng.uniform(0.55, 1.2))
        return p
    if family == "jpeg":
        return {"quality": int(rng.integers(4, 36))}
    if family == "haze":
        a = float(rng.uniform(0.6, 0.95))
        tint = rng.uniform(-0.04, 0.04, 3)
        return {"airlight": [float(np.clip(a + t, 0.0, 1.0)) for t in tint],
                "t20": float(rng.uniform(0.35, 0.85))}  # transmission at 20 m
    raise InputError(f"unknown single family {family!r}; expected one of {SINGLE}")


def _radius(h: int, w: int) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    return np.hypot(x + 0.5 - w / 2, y + 0.5 - h / 2) / (0.5 * math.hypot(w, h))


def _kernel(shape: str, size: float, angle_deg: float) -> np.ndarray:
    if shape == "gaussian":
        n = max(int(math.ceil(3 * size)), 1)
        x = np.arange(-n, n + 1)
        g = np.exp(-0.5 * (x / size) ** 2)
        return np.outer(g, g)
    if shape == "box":
        n = max(int(round(size)), 2)
        return np.ones((n, n))
    if shape == "disc":
        r = max(size, 1.0)
        n = int(math.ceil(r))
        y, x = np.mgrid[-n:n + 1, -n:n + 1]
        return (np.hypot(x, y) <= r).astype(np.float64)
    length = max(size, 2.0)  # a line of this length at angle_deg, drawn anti-aliased
    n = int(math.ceil(length / 2)) + 1
    k = np.zeros((2 * n + 1, 2 * n + 1), np.float32)
    a = math.radians(angle_deg)
    dx, dy = 0.5 * length * math.cos(a), -0.5 * length * math.sin(a)
    cv2.line(k, (round(16 * (n - dx)), round(16 * (n - dy))), (round(16 * (n + dx)), round(16 * (n + dy))), 1.0,
             1, cv2.LINE_AA, 4)
    return k.astype(np.float64)


def _pseudo_depth(h: int, w: int) -> np.ndarray:
    """A ground-plane depth from the image rows (horizon at 45 % of the height) where no depth map is given."""
    rows = (np.arange(h) + 0.5) / h
    d = np.where(rows > 0.47, 1.6 / np.maximum(rows - 0.45, 1e-3), 80.0)
    return np.broadcast_to(np.clip(d, 1.0, 80.0)[:, None], (h, w))


def apply_family(family: str, p: dict[str, Any], img: np.ndarray, depth: np.ndarray | None,
                 rng: np.random.Generator) -> np.ndarray:
    """Apply one single-family member with parameters ``p`` to an 8-bit RGB frame."""
    h, w = img.shape[:2]
    v = img.astype(np.float64) / 255.0
    if family == "tone":
        grid = np.linspace(0.0, 1.0, 256)
        luts = [_u8(_pchip(p["knots"], c, grid)) for c in p["curves"]]
        if len(luts) == 1:
            return cv2.LUT(img, luts[0])
        return np.dstack([cv2.LUT(np.ascontiguousarray(img[..., c]), luts[c]) for c in range(3)])
    if family == "noise":
        fixed = np.random.default_rng(p["pattern_seed"])
        gain = 1.0 + p["prnu"] * fixed.standard_normal((h, w, 1))
        offset = p["dsnu"] * fixed.standard_normal((h, w, 1))
        fw = p["full_well_e"]
        e = rng.poisson(np.clip(_lin(v) * gain, 0.0, None) * fw).astype(np.float64)
        e += rng.normal(0.0, p["read_e"], e.shape)
        return _u8(_enc(e / fw + offset))
    if family == "blur":
        k = _kernel(p["shape"], p["size_frac"] * w, p["angle_deg"])
        return cv2.filter2D(img, -1, (k / k.sum()).astype(np.float32), borderType=cv2.BORDER_REFLECT)
    if family == "falloff":
        r = _radius(h, w)
        if p["law"] == "cos4":
            g = np.cos(np.arctan(r * math.tan(math.radians(p["half_fov_deg"])))) ** 4
        elif p["law"] == "poly":
            g = np.clip(1.0 - p["a"] * r ** 2 - p["b"] * r ** 4, 0.05, 1.0)
        else:
            g = np.exp(-0.5 * (r / p["sigma"]) ** 2)
        g = g[..., None]
        return _u8(_enc(_lin(v) * g)) if p["linear"] else _u8(v * g)
    if family == "jpeg":
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, p["quality"]])
        if not ok:
            raise RuntimeError("OpenCV could not encode a JPEG")
        dec = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        if dec is None:
            raise RuntimeError("OpenCV could not decode its own JPEG")
        return cv2.cvtColor(dec, cv2.COLOR_BGR2RGB)
    if family == "haze":
        d = _pseudo_depth(h, w) if depth is None else np.nan_to_num(
            cv2.resize(depth.astype(np.float32), (w, h), interpolation=cv2.INTER_NEAREST), nan=80.0, posinf=80.0)
        beta = -math.log(p["t20"]) / 20.0
        t = np.exp(-beta * np.clip(d, 0.0, 200.0))[..., None]
        return _u8(_enc(_lin(v) * t + _lin(np.asarray(p["airlight"]))[None, None, :] * (1.0 - t)))
    raise InputError(f"unknown single family {family!r}; expected one of {SINGLE}")


def _pchip(xs: list[float], ys: list[float], grid: np.ndarray) -> np.ndarray:
    """A monotone cubic through the knots (Fritsch-Carlson slopes): no overshoot, monotone like the knots."""
    x, y = np.asarray(xs, np.float64), np.asarray(ys, np.float64)
    hk = np.diff(x)
    dk = np.diff(y) / hk
    m = np.zeros_like(y)
    m[0], m[-1] = dk[0], dk[-1]
    for i in range(1, len(x) - 1):
        if dk[i - 1] * dk[i] > 0:
            w1, w2 = 2 * hk[i] + hk[i - 1], hk[i] + 2 * hk[i - 1]
            m[i] = (w1 + w2) / (w1 / dk[i - 1] + w2 / dk[i])
    j = np.clip(np.searchsorted(x, grid, side="right") - 1, 0, len(x) - 2)
    t = (grid - x[j]) / hk[j]
    h00, h10, h01, h11 = 2 * t ** 3 - 3 * t ** 2 + 1, t ** 3 - 2 * t ** 2 + t, -2 * t ** 3 + 3 * t ** 2, t ** 3 - t ** 2
    return h00 * y[j] + h10 * hk[j] * m[j] + h01 * y[j + 1] + h11 * hk[j] * m[j + 1]


@dataclass(frozen=True)
class HiddenCase:
    """One hidden effect: its ``family``, the single families it is made of (``parts``, in the order
    applied) with their parameters, and the seed that drew it (and draws its per-frame noise)."""

    family: str
    seed: int
    parts: tuple[tuple[str, dict[str, Any]], ...] = field(default=())

    @property
    def accepted(self) -> tuple[str, ...]:
        """Names the workflow may give it (any part's)."""
        return tuple(n for f, _ in self.parts for n in ACCEPTED[f])

    def label(self) -> str:
        """A short description: ``"blur(disc 0.006)+noise"``."""
        def one(f: str, p: dict[str, Any]) -> str:
            sub = {"blur": p.get("shape"), "falloff": p.get("law"), "jpeg": f"q{p.get('quality')}",
                   "tone": "colour" if p.get("colour") else "grey"}.get(f)
            return f"{f}({sub})" if sub else f
        return "+".join(one(f, p) for f, p in self.parts) or "none"

    def apply(self, img: np.ndarray, depth: np.ndarray | None, frame: int) -> np.ndarray:
        """The frame with the hidden effect; the random parts are drawn from (seed, frame)."""
        rng = np.random.default_rng([self.seed, 0x4D1D, frame])
        out = img
        for f, p in self.parts:
            out = apply_family(f, p, out, depth, rng)
        return out if self.parts else img.copy()


def draw_case(family: str, seed: int) -> HiddenCase:
    """The member of ``family`` (one of :data:`FAMILIES`) that ``seed`` draws."""
    if family not in FAMILIES:
        raise InputError(f"unknown family {family!r}; expected one of {FAMILIES}")
    rng = np.random.default_rng([seed, FAMILIES.index(family)])
    if family == "none":
        return HiddenCase("none", seed, ())
    if family == "pair":
        a, b = rng.choice(len(SINGLE), 2, replace=False)
        names = sorted((SINGLE[int(a)], SINGLE[int(b)]), key=ORDER.index)
        return HiddenCase("pair", seed, tuple((n, draw_params(n, rng)) for n in names))
    return HiddenCase(family, seed, ((family, draw_params(family, rng)),))
