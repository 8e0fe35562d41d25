"""Compare simulated and measured frames, with a bootstrap over frames so that noise is not a gap.

**Image signals.** Each signal ``s`` is put on a common scale ``sigma_s``: the robust spread of the
measured signal across frames (1.4826 MAD), never below the signal's ``floor`` (the smallest
difference worth reporting, :data:`~weather_gym.lab.gap.signals.SIGNALS`). The standardised bias of a
simulation is ``b_s = mean(sim_s - measured_s) / sigma_s`` (paired: mean of per-frame differences;
unpaired: difference of means).

**The gap** (one scalar, lower is better) is the weighted root mean square of the standardised
biases, every signal family weighing the same: ``gap = sqrt(sum_s w_s b_s^2 / sum_s w_s)``.
A gap of 1 means the simulation is off by one scene-to-scene spread on a typical signal.

**Difference in differences** (``reference`` and ``base`` given): the bias is the change the model
makes to clean simulator frames minus the change measured from the clear reference to the measured
frames, ``b_s = [mean(sim_s - base_s) - (mean(measured_s) - mean(reference_s))] / sigma_s``: what
already differs between the clear reference and the simulator (the domain) cancels.

**Significance.** The difference of every signal (image and perception) is bootstrapped over
frames (resampling frames jointly in paired mode, each set on its own in unpaired mode). The
effect size is ``difference / bootstrap std``; its two-sided p-value (normal approximation) is
tested with Holm's step-down correction over all the signals of a level at ``alpha`` (0.01), and a
difference is only reported as significant when it is also at least ``min_effect`` (0.5) of the
signal's scale (perception: 0.01 in AP / recall / score, 0.05 false positives per frame).

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.gap.compare import GapMeter, holm
    >>> meas = np.zeros((20, 2)); sim = np.ones((20, 2))
    >>> m = GapMeter(meas, scale=np.ones(2), weights=np.ones(2), paired=True)
    >>> round(m.gap(sim), 3), round(m.gap(meas), 3)
    (1.0, 0.0)
    >>> holm(np.array([0.001, 0.04, 0.2]), 0.05).tolist()
    [True, False, False]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from statistics import NormalDist
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.lab.gap.perception import FrameMatches, perception_stats
from weather_gym.lab.gap.signals import SIGNALS

__all__ = ["ALPHA", "MIN_EFFECT", "GapMeter", "signal_scale", "bootstrap_weights", "compare_signals",
           "compare_perception", "compare_perception_did", "holm", "gap_test"]

ALPHA = 0.01
MIN_EFFECT = 0.5
PERCEPTION_MIN_DIFF = {"fp_per_frame": 0.05}
PERCEPTION_DEFAULT_MIN_DIFF = 0.01
_Z_CAP = 1e6


def signal_scale(measured: np.ndarray) -> np.ndarray:
    """``sigma_s``: robust spread of each measured signal across frames, at least its floor."""
    floors = np.array([s.floor for s in SIGNALS])
    out = floors.copy()
    for j in range(measured.shape[1]):
        v = measured[:, j]
        v = v[np.isfinite(v)]
        if v.size >= 3:
            out[j] = max(1.4826 * float(np.median(np.abs(v - np.median(v)))), floors[j])
    return out


def bootstrap_weights(n: int, b: int, rng: np.random.Generator) -> np.ndarray:
    """``(b, n)`` frame counts of ``b`` bootstrap resamples of ``n`` frames."""
    return rng.multinomial(n, np.full(n, 1.0 / n), size=b).astype(np.float64)


def _wmean(w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Weighted means of the columns of ``x`` (NaN-aware) for each row of weights ``w``."""
    ok = np.isfinite(x)
    num = w @ np.where(ok, x, 0.0)
    den = w @ ok.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


def _gap_of(bias: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted RMS over the last axis, ignoring NaN biases."""
    ok = np.isfinite(bias)
    w = np.where(ok, weights, 0.0)
    num = (w * np.where(ok, bias, 0.0) ** 2).sum(axis=-1)
    den = w.sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, np.sqrt(num / np.where(den > 0, den, 1.0)), np.nan)


class GapMeter:
    """The image-signal gap of simulated signals against fixed measured signals (see module doc).

    ``measured``: ``(N, S)`` signals; in paired mode ``sim`` arrays passed later are ``(N, S)`` of
    the same frames, in unpaired mode ``(M, S)`` of other frames.
    """

    def __init__(self, measured: np.ndarray, *, scale: np.ndarray, weights: np.ndarray, paired: bool,
                 reference: np.ndarray | None = None, base: np.ndarray | None = None,
                 ref_paired: bool = False) -> None:
        self.measured = np.asarray(measured, np.float64)
        self.scale = np.asarray(scale, np.float64)
        self.weights = np.asarray(weights, np.float64)
        self.paired = paired
        self.reference = None if reference is None else np.asarray(reference, np.float64)
        self.base = None if base is None else np.asarray(base, np.float64)
        self.ref_paired = ref_paired

    @property
    def did(self) -> bool:
        """Difference in differences (a clear reference and clean simulator signals are set)."""
        return self.reference is not None

    def _check(self, sim: np.ndarray) -> np.ndarray:
        sim = np.asarray(sim, np.float64)
        if self.did:
            if self.base is None or sim.shape != self.base.shape:
                raise InputError("difference in differences needs the clean simulator signals (base) of the same "
                                 f"frames: base {None if self.base is None else self.base.shape}, sim {sim.shape}")
        elif self.paired and sim.shape != self.measured.shape:
            raise InputError(f"paired comparison needs sim signals of shape {self.measured.shape}, got {sim.shape}")
        return sim

    def measured_change(self) -> np.ndarray:
        """DiD: the measured change ``mean(measured) - mean(reference)`` of every signal."""
        if self.ref_paired:
            return _nanmean(self.measured - self.reference)  # type: ignore[operator]  # DiD: a reference
        with np.errstate(invalid="ignore"):
            return _nanmean(self.measured) - _nanmean(self.reference)  # type: ignore[arg-type]  # DiD: a reference

    def summary(self, sim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(sim, measured)`` per signal as reported: the means, or (DiD) the two changes."""
        sim = self._check(sim)
        if self.did:
            return _nanmean(sim - self.base), self.measured_change()
        return _nanmean(sim), _nanmean(self.measured)

    def biases(self, sim: np.ndarray) -> np.ndarray:
        """Standardised bias ``b_s`` of every signal."""
        sim = self._check(sim)
        if self.did:
            return (_nanmean(sim - self.base) - self.measured_change()) / self.scale
        if self.paired:
            d = sim - self.measured
            ok = np.isfinite(d)
            mean = np.where(ok.any(0), np.where(ok, d, 0).sum(0) / np.maximum(ok.sum(0), 1), np.nan)
        else:
            with np.errstate(invalid="ignore"):
                mean = _nanmean(sim) - _nanmean(self.measured)
        return mean / self.scale

    def gap(self, sim: np.ndarray) -> float:
        return float(_gap_of(self.biases(sim), self.weights))

    def residuals(self, sim: np.ndarray) -> np.ndarray:
        """``sqrt(w_s / sum w) * b_s`` with undefined biases as 0: ``gap == norm(residuals)``
        whenever every signal is defined (the form least-squares fitting needs)."""
        b = self.biases(sim)
        ok = np.isfinite(b)
        w = np.where(ok, self.weights, 0.0)
        return np.sqrt(w / max(w.sum(), 1e-12)) * np.where(ok, b, 0.0)

    def bootstrap_biases(self, sims: Sequence[np.ndarray], b: int, rng: np.random.Generator) -> list[np.ndarray]:
        """``(b, S)`` bootstrap biases for each of ``sims``, all on the same resamples of frames."""
        sims = [self._check(s) for s in sims]
        wm = bootstrap_weights(self.measured.shape[0], b, rng)
        if self.did:
            ws = bootstrap_weights(sims[0].shape[0], b, rng) if sims else None
            if self.ref_paired:
                target = _wmean(wm, self.measured - self.reference)  # type: ignore[operator]  # DiD: a reference
            else:
                wr = bootstrap_weights(self.reference.shape[0], b, rng)  # type: ignore[union-attr]  # DiD: a reference
                target = _wmean(wm, self.measured) - _wmean(wr, self.reference)  # type: ignore[arg-type]  # DiD: a reference
            return [(_wmean(ws, s - self.base) - target) / self.scale for s in sims]  # type: ignore[arg-type]  # ws: set when sims is not empty
        if self.paired:
            return [_wmean(wm, s - self.measured) / self.scale for s in sims]
        ws = bootstrap_weights(sims[0].shape[0], b, rng) if sims else None
        mm = _wmean(wm, self.measured)
        return [(_wmean(ws, s) - mm) / self.scale for s in sims]  # type: ignore[arg-type]  # ws: set when sims is not empty

    def bootstrap_gaps(self, sims: Sequence[np.ndarray], b: int, rng: np.random.Generator) -> np.ndarray:
        """``(b, len(sims))`` bootstrap gaps, all models on the same resamples."""
        return np.stack([_gap_of(x, self.weights) for x in self.bootstrap_biases(sims, b, rng)], axis=1)


def _nanmean(x: np.ndarray) -> np.ndarray:
    ok = np.isfinite(x)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok.any(0), np.where(ok, x, 0).sum(0) / np.maximum(ok.sum(0), 1), np.nan)


def holm(pvalues: np.ndarray, alpha: float) -> np.ndarray:
    """Holm's step-down test: which hypotheses are rejected at family-wise level ``alpha`` (NaN: never)."""
    p = np.asarray(pvalues, np.float64)
    ok = np.isfinite(p)
    rejected = np.zeros(p.shape, bool)
    idx = np.flatnonzero(ok)
    order = idx[np.argsort(p[idx], kind="mergesort")]
    m = order.size
    for rank, i in enumerate(order):
        if p[i] <= alpha / (m - rank):
            rejected[i] = True
        else:
            break
    return rejected


def _z_and_p(diff: float, std: float) -> tuple[float, float]:
    if not math.isfinite(diff):
        return math.nan, math.nan
    if not std > 0 or not math.isfinite(std):
        if diff == 0.0:
            return 0.0, 1.0
        return math.copysign(_Z_CAP, diff), 0.0
    z = max(min(diff / std, _Z_CAP), -_Z_CAP)
    return z, 2.0 * (1.0 - NormalDist().cdf(abs(z)))


def _row(name: str, level: str, family: str, sim: float, meas: float, diff: float, boot: np.ndarray,
         standardized: float | None) -> dict[str, Any]:
    boot = boot[np.isfinite(boot)]
    std = float(boot.std(ddof=1)) if boot.size > 2 else math.nan
    z, p = _z_and_p(diff, std)
    lo, hi = (np.percentile(boot, [2.5, 97.5]).tolist() if boot.size > 2 else [math.nan, math.nan])
    row = {"signal": name, "level": level, "family": family, "sim": sim, "measured": meas, "difference": diff,
           "ci95": [lo, hi], "effect_size": z, "p_value": p}
    if standardized is not None:
        row["standardized"] = standardized
    return row


def compare_signals(meter: GapMeter, sim: np.ndarray, *, b: int = 1000, seed: int = 0,
                    alpha: float = ALPHA, min_effect: float = MIN_EFFECT) -> list[dict[str, Any]]:
    """One row per image signal: means, difference (sim - measured) with bootstrap CI, effect size,
    p-value, standardised bias, significance (Holm at ``alpha`` and ``|b_s| >= min_effect``)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xC0]))
    boot = meter.bootstrap_biases([sim], b, rng)[0] * meter.scale
    bias = meter.biases(sim)
    sim_mean, meas_mean = meter.summary(sim)
    rows = []
    for j, s in enumerate(SIGNALS):
        diff = float(bias[j] * meter.scale[j])
        rows.append(_row(s.name, "image", s.family, float(sim_mean[j]), float(meas_mean[j]), diff, boot[:, j],
                         float(bias[j])))
    sig = holm(np.array([r["p_value"] for r in rows]), alpha)
    for r, s in zip(rows, sig):
        r["significant"] = bool(s and abs(r["standardized"]) >= min_effect)
    return rows


def compare_perception(sim: FrameMatches, measured: FrameMatches, *, paired: bool, b: int = 300, seed: int = 0,
                       alpha: float = ALPHA) -> list[dict[str, Any]]:
    """One row per detector statistic (see :func:`~weather_gym.lab.gap.perception.perception_stats`)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xBE]))
    s0, m0 = perception_stats(sim), perception_stats(measured)
    wm = bootstrap_weights(measured.n_frames, b, rng)
    ws = wm if paired else bootstrap_weights(sim.n_frames, b, rng)
    names = list(s0)
    boot = np.empty((b, len(names)))
    for i in range(b):
        bs, bm = perception_stats(sim, ws[i]), perception_stats(measured, wm[i])
        boot[i] = [bs[n] - bm[n] for n in names]
    rows = []
    for j, n in enumerate(names):
        diff = s0[n] - m0[n]
        rows.append(_row(n, "perception", "perception", s0[n], m0[n], diff, boot[:, j], None))
    sig = holm(np.array([r["p_value"] for r in rows]), alpha)
    for r, s in zip(rows, sig):
        need = PERCEPTION_MIN_DIFF.get(r["signal"], PERCEPTION_DEFAULT_MIN_DIFF)
        r["significant"] = bool(s and abs(r["difference"]) >= need)
    return rows


def compare_perception_did(sim: FrameMatches, sim_clean: FrameMatches, measured: FrameMatches,
                           reference: FrameMatches, *, ref_paired: bool, b: int = 300, seed: int = 0,
                           alpha: float = ALPHA) -> tuple[list[dict[str, Any]], dict[str, dict[str, float]]]:
    """Difference in differences of every detector statistic: ``(sim - sim_clean) - (measured -
    reference)``; rows as :func:`compare_perception` (``sim`` / ``measured`` hold the two changes)
    and the four sets' statistics."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xD1D]))
    stats = {"sim": perception_stats(sim), "sim_clean": perception_stats(sim_clean),
             "measured": perception_stats(measured), "reference": perception_stats(reference)}
    ws = bootstrap_weights(sim.n_frames, b, rng)
    wm = bootstrap_weights(measured.n_frames, b, rng)
    wr = wm if ref_paired else bootstrap_weights(reference.n_frames, b, rng)
    names = list(stats["sim"])
    boot = np.empty((b, len(names)))
    for i in range(b):
        s1, s0 = perception_stats(sim, ws[i]), perception_stats(sim_clean, ws[i])
        m1, m0 = perception_stats(measured, wm[i]), perception_stats(reference, wr[i])
        boot[i] = [(s1[n] - s0[n]) - (m1[n] - m0[n]) for n in names]
    rows = []
    for j, n in enumerate(names):
        ds_ = stats["sim"][n] - stats["sim_clean"][n]
        dm = stats["measured"][n] - stats["reference"][n]
        rows.append(_row(n, "perception", "perception", ds_, dm, ds_ - dm, boot[:, j], None))
    sig = holm(np.array([r["p_value"] for r in rows]), alpha)
    for r, s_ in zip(rows, sig):
        need = PERCEPTION_MIN_DIFF.get(r["signal"], PERCEPTION_DEFAULT_MIN_DIFF)
        r["significant"] = bool(s_ and abs(r["difference"]) >= need)
    return rows, stats


def gap_test(meter: GapMeter, before: np.ndarray, after: np.ndarray, *, b: int = 1000,
             seed: int = 0) -> dict[str, Any]:
    """Bootstrap the held-out gap of two models on the same resamples of frames.

    Returns ``gap_before``, ``gap_after``, ``reduction`` (before - after), its 95 % interval and
    the one-sided p-value that the reduction is not positive (normal approximation with the
    bootstrap standard deviation, so that small p-values are resolved without huge resamples).
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x6A9]))
    g = meter.bootstrap_gaps([before, after], b, rng)
    red = g[:, 0] - g[:, 1]
    red = red[np.isfinite(red)]
    g0, g1 = meter.gap(before), meter.gap(after)
    std = float(red.std(ddof=1)) if red.size > 2 else math.nan
    z, _ = _z_and_p(g0 - g1, std)
    p = 1.0 - NormalDist().cdf(z) if math.isfinite(z) else 1.0
    return {"gap_before": g0, "gap_after": g1, "reduction": g0 - g1,
            "reduction_ci95": np.percentile(red, [2.5, 97.5]).tolist() if red.size else [math.nan, math.nan],
            "gap_before_ci95": np.percentile(g[:, 0], [2.5, 97.5]).tolist(),
            "gap_after_ci95": np.percentile(g[:, 1], [2.5, 97.5]).tolist(), "p_value": p}

