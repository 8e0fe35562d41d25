"""Domain differences: what differs between a camera and the simulator before any weather.

A real camera, lens, scene and car differ from the simulator's in many ways that are not weather:
exposure and tone mapping, sensor noise, sharpness, colour, how much is in the scene (clutter), the
car's own bodywork in the frame. In difference-in-differences mode they are measured between the
measured *clear* reference and clean simulator frames and reported here, named, and never fitted as
weather; when there is no clear reference they are what the comparison cannot tell from weather
(the report says the answer is confounded).

Names per signal family (:data:`DOMAIN_NAMES`), plus two descriptors that are not part of the gap:
``clutter`` (the fraction of the frame with strong edges: how busy the scene is) and the ``ego
vehicle`` (the part of the measured frame its ignore mask covers, or, without a mask, the part that
stays the same while the scene moves).

Example:
    >>> from weather_gym.lab.gap.domain import name_differences
    >>> rows = [{"signal": "tone_p50", "family": "tone", "significant": True, "standardized": 4.0,
    ...          "sim": 120.0, "measured": 160.0}]
    >>> [d["name"] for d in name_differences(rows)]
    ['exposure']
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from weather_gym.lab.datasets.masks import propose_mask
from weather_gym.lab.gap.compare import _z_and_p, bootstrap_weights

__all__ = ["DOMAIN_NAMES", "name_differences", "clutter", "compare_clutter", "ego_vehicle"]

DOMAIN_NAMES: dict[str, str] = {
    "tone": "exposure",
    "colour": "colour",
    "sharpness": "sharpness",
    "motion": "sharpness",
    "noise": "noise",
    "block": "compression",
    "haze": "contrast over distance",
    "vignette": "lens shading",
    "blobs": "bright flat areas",
    "cones": "cone appearance",
}


def name_differences(rows: Sequence[dict[str, Any]], extra: Sequence[dict[str, Any]] = ()) -> list[dict[str, Any]]:
    """Significant signal rows (and ``extra`` named entries) grouped into named domain differences,
    strongest first: ``{name, signals, strongest, standardized, detail}``."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        if r.get("significant") and r.get("family") in DOMAIN_NAMES:
            groups.setdefault(DOMAIN_NAMES[r["family"]], []).append(r)
    out = []
    for name, rs in groups.items():
        rs.sort(key=lambda r: -abs(r.get("standardized") or 0.0))
        top = rs[0]
        side = "higher" if (top.get("standardized") or 0.0) > 0 else "lower"
        out.append({"name": name, "signals": [r["signal"] for r in rs], "strongest": top["signal"],
                    "standardized": top.get("standardized"),
                    "detail": f"{top['signal']} is {side} in the simulator ({_g(top.get('sim'))} vs "
                              f"{_g(top.get('measured'))} measured; {abs(top.get('standardized') or 0.0):.1f} "
                              "scene-to-scene spreads)"})
    out += [dict(e) for e in extra]
    out.sort(key=lambda d: -abs(d.get("standardized") or 0.0))
    return out


def _g(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, int | float) and math.isfinite(v) else "n/a"


def clutter(image: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Fraction of the frame (outside ``mask``) at half resolution whose gradient exceeds 10 % of the
    luma range (5th to 95th percentile): how much structure the scene holds."""
    y = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    h, w = y.shape
    yh = cv2.resize(y, (w // 2, h // 2), interpolation=cv2.INTER_AREA).astype(np.float32)
    gx = cv2.Sobel(yh, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(yh, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    mag = cv2.magnitude(gx, gy)
    used = np.ones(yh.shape, bool) if mask is None else cv2.resize(
        np.asarray(mask, np.uint8), (w // 2, h // 2), interpolation=cv2.INTER_NEAREST) == 0
    if used.sum() < 100:
        return math.nan
    lo, hi = np.percentile(yh[used], [5, 95])
    return float((mag[used] > 0.1 * max(hi - lo, 1.0)).mean())


def compare_clutter(sim: Sequence[float], measured: Sequence[float], *, b: int = 1000, seed: int = 0,
                    alpha: float = 0.01) -> dict[str, Any] | None:
    """A domain entry when the simulator's clutter differs significantly from the measured (bootstrap
    of the difference of means; at least half the measured spread), else None."""

    s, m = np.asarray(sim, np.float64), np.asarray(measured, np.float64)
    s, m = s[np.isfinite(s)], m[np.isfinite(m)]
    if s.size < 3 or m.size < 3:
        return None
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xC1]))
    ws, wm = bootstrap_weights(s.size, b, rng), bootstrap_weights(m.size, b, rng)
    boot = ws @ s / s.size - wm @ m / m.size
    diff = float(s.mean() - m.mean())
    _, p = _z_and_p(diff, float(boot.std(ddof=1)))
    spread = max(float(np.std(m, ddof=1)), 0.01)
    if not (p < alpha and abs(diff) >= 0.5 * spread):
        return None
    side = "less" if diff < 0 else "more"
    return {"name": "clutter", "signals": ["clutter"], "strongest": "clutter", "standardized": diff / spread,
            "detail": f"the simulator's scenes hold {side} structure: strong edges cover {100 * s.mean():.1f} % of "
                      f"its frames against {100 * m.mean():.1f} % measured"}


def ego_vehicle(frames: Sequence[np.ndarray], masks: Sequence[np.ndarray | None]) -> dict[str, Any] | None:
    """A domain entry for the car's own bodywork in the measured frames: the ignore mask's share of
    the frame, or, without a mask, the static region :func:`~weather_gym.lab.datasets.masks.propose_mask`
    finds (then unmasked, so it is in every comparison). None when neither covers 2 % of the frame."""
    given = [m for m in masks if m is not None]
    if given:
        share = float(np.mean([m.mean() for m in given]))
        if share < 0.02:
            return None
        return {"name": "ego vehicle", "signals": [], "strongest": "ignore mask", "standardized": None,
                "share": share, "masked": True,
                "detail": f"the measured camera sees its own car: {100 * share:.0f} % of the frame is in the ignore "
                          "mask (skipped by every comparison); the simulator's camera sees none"}
    if len(frames) < 4:
        return None

    try:
        share = float(propose_mask(list(frames)[:60]).mean())
    except ValueError:
        return None
    if share < 0.02:
        return None
    return {"name": "ego vehicle", "signals": [], "strongest": "static region", "standardized": None,
            "share": share, "masked": False,
            "detail": f"about {100 * share:.0f} % of the measured frame stays the same while the scene moves "
                      "(probably the car's own bodywork) and is not masked, so it is in every comparison: mask it "
                      "(weather-gym dataset mask DIR --out MASK.png, then --set)"}
