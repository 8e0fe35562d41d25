"""Fit a weather effect's parameters so that simulated frames match measured ones.

The objective is the image-signal gap (:class:`~weather_gym.lab.gap.compare.GapMeter`) on the
fitting frames, with every effect's random numbers fixed per frame (common random numbers), so it
is a deterministic function of the parameters. The search is cheap and derivative-free:

1. ``screen``: ``k`` on a coarse grid (:data:`K_GRID`) with the other parameters at their defaults;
2. ``fit``: ``k`` refined by a bounded Brent search between the grid neighbours of the best point,
   then ``k`` and the effect's other fittable parameters (``PARAM_BOUNDS``) together by bounded
   least squares on the standardised biases (the gap is their weighted norm; trust-region
   Gauss-Newton with a finite-difference Jacobian) in normalised coordinates (logarithmic for wide
   positive ranges). The extra
   parameters are kept only if they cut the gap by more than :data:`PENALTY` (relative) per
   parameter that moved; parameters that do not change the output at all (e.g. the physical-mode
   settings of ``dim`` in its faithful mode) are found by a one-frame probe and left alone. A
   parameter that only rescales ``k`` (:data:`SCALE_PARAMS`, e.g. ``blur``'s ``max_radius_frac``)
   is fitted only when ``k`` ends at 1, to extend its range.

Effects with choices (``dim`` mode, ``exposure`` direction) are fitted once per choice.

Example:
    >>> from weather_gym.lab.gap.fit import candidates
    >>> [c.describe() for c in candidates([], names=["exposure"])]
    ['exposure(direction=under)', 'exposure(direction=over)']
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections import OrderedDict
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from weather_gym.lab.gap.compare import GapMeter
from weather_gym.lab.gap.signals import SignalMask, frame_signals, signal_mask
from weather_gym.lab.gap.weather_model import apply_chain, insert_position
from weather_gym.weather import EFFECTS, KnobEffect, make

__all__ = ["K_GRID", "PENALTY", "SCALE_PARAMS", "Candidate", "FitResult", "Evaluator", "candidates", "screen", "fit",
           "refit", "refit_joint", "fit_summary", "bounds_hit", "bound_ends", "scale_params", "NATURAL_ENDS"]

K_GRID: tuple[float, ...] = (0.08, 0.2, 0.4, 0.7, 1.0)
PENALTY = 0.05

#: The parameter of an effect that only rescales k (the output depends on their product): it is
#: fitted only when k ends at 1, to extend k's range, and never together with k. Where an effect has
#: several (one per kind), the first that changes the output is used.
SCALE_PARAMS: dict[str, str | tuple[str, ...]] = {
    "blur": "max_radius_frac",
    "noise": "max_gain",
    "exposure": "max_stops",
    "fog": "min_visibility_m",
    "jpeg": "min_quality",
    "motion_blur": ("exposure_s", "max_length_frac"),
    "dim": "stops",
}


def scale_params(name: str) -> tuple[str, ...]:
    """The scale parameter(s) of effect ``name`` (see :data:`SCALE_PARAMS`)."""
    v = SCALE_PARAMS.get(name, ())
    return (v,) if isinstance(v, str) else tuple(v)


#: Parameter ends where a component of the effect is absent (no read noise, no flare, no veil): a fit
#: resting there is a valid fit of the rest of the effect, not a range that clips it.
NATURAL_ENDS: dict[str, dict[str, str]] = {
    "noise": {"read_noise_e": "lo"},
    "dim": {"read_noise_e": "lo", "denoise_px": "lo", "chroma_noise": "lo", "black_level": "lo", "desaturate": "lo"},
    "exposure": {"flare": "lo"},
    "glare": {"veil": "lo", "bloom": "lo"},
    "rain": {"haze": "lo"},
}


def bound_ends(effect: KnobEffect, extras: Sequence[str] = ()) -> list[dict[str, Any]]:
    """Every parameter of a fitted effect that ends on the edge of its range: ``k`` at 1 (without its
    scale parameter extending the range) or a fitted parameter (``extras``) at a bound, each with
    ``natural`` True when that end means the component is absent (:data:`NATURAL_ENDS`)."""
    out: list[dict[str, Any]] = []
    if getattr(effect, "MEASURED", False):  # a measured curve has no range to clip it (k = 1: as measured)
        return out
    if effect.k >= 0.995 and not any(p in extras for p in scale_params(effect.name)):
        out.append({"param": "k", "value": float(effect.k), "lo": 0.0, "hi": 1.0, "end": "hi", "natural": False,
                    "text": "k = 1 (the top of its range)"})
    natural = NATURAL_ENDS.get(effect.name, {})
    for p in extras:
        lo, hi = type(effect).bounds_of(p)
        v = float(getattr(effect, p))
        u = _to_unit(v, lo, hi)
        if u <= 0.005 or u >= 0.995:
            end = "lo" if u <= 0.005 else "hi"
            out.append({"param": p, "value": v, "lo": lo, "hi": hi, "end": end, "natural": natural.get(p) == end,
                        "text": f"{p} = {v:.4g} (bound of {lo:g}..{hi:g})"})
    return out


def bounds_hit(effect: KnobEffect, extras: Sequence[str] = ()) -> list[str]:
    """Where a fitted effect's range clips the fit: ``k`` at 1 without its scale parameter extending
    the range, or a fitted parameter (``extras``) at a bound that is not a natural end (a read noise
    or a flare at zero is the component being absent: a valid fit). See :func:`bound_ends`."""
    return [b["text"] for b in bound_ends(effect, extras) if not b["natural"]]


@dataclass(frozen=True)
class Candidate:
    """An effect that may be missing: its registry name and fixed choices (e.g. ``direction``)."""

    name: str
    choices: tuple[tuple[str, str], ...] = ()

    def template(self, k: float = 0.0) -> KnobEffect:
        return make(self.name, k=k, **dict(self.choices))

    def describe(self) -> str:
        return self.name + (f"({', '.join(f'{a}={b}' for a, b in self.choices)})" if self.choices else "")


def candidates(model: Sequence[KnobEffect], names: Sequence[str] | None = None) -> list[Candidate]:
    """Every registered effect not already in ``model`` (or only ``names``), one per choice combination."""
    present = {e.name for e in model}
    out = []
    for name in (names if names is not None else EFFECTS.names()):
        cls = EFFECTS.get(name)
        if name in present:
            continue
        combos: list[tuple[tuple[str, str], ...]] = [()]
        for param, allowed in cls.CHOICES.items():
            combos = [c + ((param, v),) for c in combos for v in allowed]
        out += [Candidate(name, c) for c in combos]
    return out


@dataclass
class FitResult:
    """A fitted effect: where it goes in the chain, its gap on the fitting frames, how many
    parameters it uses (``k`` plus the extras that moved), and the search trace."""

    candidate: Candidate
    effect: KnobEffect
    position: int
    fit_gap: float
    n_params: int
    curve: list[tuple[float, float]] = field(default_factory=list)
    n_evals: int = 0
    extras: list[str] = field(default_factory=list)

    @property
    def penalized(self) -> float:
        return self.fit_gap * (1.0 + PENALTY * self.n_params)


_POOL: ThreadPoolExecutor | None = None


def _map(fn: Callable[[int], Any], n: int) -> list:
    """``[fn(i) for i in range(n)]`` on a small thread pool (OpenCV and numpy release the GIL; every
    frame has its own seeded generator, so the result does not depend on the order)."""
    global _POOL
    workers = min(os.cpu_count() or 1, 4)
    if n < 4 or workers < 2:
        return [fn(i) for i in range(n)]
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="gap")
    return list(_POOL.map(fn, range(n)))


def _key(effects: Sequence[KnobEffect]) -> tuple:
    return tuple((e.name, tuple(sorted(e.params().items()))) for e in effects)


class Evaluator:
    """Applies weather models to a fixed set of clean simulated frames and measures the gap.

    ``images``/``depths``/``states``/``ids``: the clean frames; ``signal_depths``/``signal_boxes``:
    what the signals use; ``meter``: the gap against the measured signals of the same frames
    (paired) or of the measured fitting set (unpaired). Outputs of a model prefix are cached, so a
    candidate inserted at the end of the chain costs one effect per frame.
    """

    def __init__(self, images: Sequence[np.ndarray], depths: Sequence[np.ndarray | None],
                 states: Sequence[dict], ids: Sequence[int], signal_depths: Sequence[np.ndarray | None],
                 signal_boxes: Sequence[np.ndarray | None], meter: GapMeter, *, seed: int = 0,
                 cache_size: int = 3, signal_masks: Sequence[np.ndarray | None] | None = None) -> None:
        self.images, self.depths, self.states, self.ids = list(images), list(depths), list(states), list(ids)
        self.signal_depths, self.signal_boxes = list(signal_depths), list(signal_boxes)
        prepared: dict[int, SignalMask | None] = {}
        self.signal_masks: list[SignalMask | None] = []
        for m in (signal_masks if signal_masks is not None else [None] * len(self.images)):
            if m is not None and id(m) not in prepared:
                prepared[id(m)] = signal_mask(m)
            self.signal_masks.append(None if m is None else prepared[id(m)])
        self.meter = meter
        self.seed = int(seed)
        self.n_evals = 0
        self._prefix: OrderedDict[tuple, list[np.ndarray]] = OrderedDict()
        self._cache_size = cache_size

    def __len__(self) -> int:
        return len(self.images)

    def _apply(self, effects: Sequence[KnobEffect], frames: Sequence[np.ndarray]) -> list[np.ndarray]:
        if not effects:
            return list(frames)

        def one(i: int) -> np.ndarray:  # own copies: an effect's episode state is not shared between threads
            return apply_chain([dataclasses.replace(e) for e in effects], frames[i], depth=self.depths[i],
                               state=self.states[i], seed=self.seed, frame_id=self.ids[i])

        return _map(one, len(frames))

    def prefix(self, effects: Sequence[KnobEffect]) -> list[np.ndarray]:
        key = _key(effects)
        out = self._prefix.get(key)
        if out is None:
            out = self._apply(effects, self.images)
            self._prefix[key] = out
            while len(self._prefix) > self._cache_size:
                self._prefix.popitem(last=False)
        else:
            self._prefix.move_to_end(key)
        return out

    def frames(self, model: Sequence[KnobEffect], split: int | None = None) -> list[np.ndarray]:
        """The frames under ``model``; ``split``: the prefix ``model[:split]`` comes from the cache."""
        split = len(model) if split is None else split
        return self._apply(model[split:], self.prefix(model[:split]))

    def signals(self, model: Sequence[KnobEffect], split: int | None = None) -> np.ndarray:
        frames = self.frames(model, split)
        self.n_evals += 1
        return np.stack(_map(lambda i: frame_signals(frames[i], self.signal_depths[i], self.signal_boxes[i],
                                                     self.signal_masks[i]), len(frames)))

    def gap(self, model: Sequence[KnobEffect], split: int | None = None) -> float:
        return self.meter.gap(self.signals(model, split))


def _scale(lo: float, hi: float) -> bool:
    """Search a parameter on a log scale (wide positive range)?"""
    return lo > 0 and hi / lo > 20


def _to_unit(v: float, lo: float, hi: float) -> float:
    if _scale(lo, hi):
        return (math.log(v) - math.log(lo)) / (math.log(hi) - math.log(lo))
    return (v - lo) / (hi - lo)


def _from_unit(u: float, lo: float, hi: float) -> float:
    u = min(max(u, 0.0), 1.0)
    if _scale(lo, hi):
        return float(math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo))))
    return float(lo + u * (hi - lo))


def live_params(effect: KnobEffect, image: np.ndarray, depth: np.ndarray | None, state: dict) -> list[str]:
    """The ``PARAM_BOUNDS`` parameters that change the output of ``effect`` on ``image``."""
    probe = effect if effect.k > 0 else effect.with_params(k=0.5)

    def run(e: KnobEffect) -> np.ndarray:
        return apply_chain([e], image, depth=depth, state=state, seed=0, frame_id=0)

    base = run(probe)
    live = []
    for p, (lo, hi) in type(effect).PARAM_BOUNDS.items():
        for v in (lo, hi, 0.5 * (lo + hi)):
            if v == getattr(probe, p):
                continue
            if not np.array_equal(run(probe.with_params(**{p: v})), base):
                live.append(p)
                break
    return live


def _round(v: float) -> float:
    return float(f"{v:.4g}")


def _with(effect: KnobEffect, **params: float) -> KnobEffect:
    cls = type(effect)
    clean = {}
    for p, v in params.items():
        lo, hi = cls.bounds_of(p)
        v = min(max(_round(v), lo), hi)
        clean[p] = int(round(v)) if isinstance(getattr(effect, p), int) and not isinstance(getattr(effect, p), bool) else v
    return effect.with_params(**clean)


def _brent(f: Callable[[float], float], lo: float, hi: float, maxiter: int) -> tuple[float, float]:
    if hi - lo < 1e-3:
        return lo, f(lo)
    r = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 0.005, "maxiter": maxiter})
    return float(r.x), float(r.fun)


def _least_squares(f: Callable[[np.ndarray], np.ndarray], u0: np.ndarray, max_nfev: int) -> np.ndarray:
    """Bounded Gauss-Newton (trust region, finite-difference Jacobian) in unit coordinates."""

    u0 = np.clip(u0, 1e-6, 1.0 - 1e-6)
    r = least_squares(f, u0, bounds=(0.0, 1.0), method="trf", diff_step=0.05, max_nfev=max_nfev,
                      xtol=1e-4, ftol=1e-3, x_scale=1.0)
    return np.clip(r.x, 0.0, 1.0)


class _Objective:
    """Standardised biases (and so the gap) of ``base`` with ``effect`` at ``position``, memoised."""

    def __init__(self, ev: Evaluator, base: Sequence[KnobEffect], position: int) -> None:
        self.ev, self.base, self.position = ev, list(base), position
        self.memo: dict[tuple, np.ndarray] = {}

    def residuals(self, effect: KnobEffect) -> np.ndarray:
        """``sqrt(w_s / sum w) * b_s`` (0 where undefined): the gap is their Euclidean norm."""
        key = _key([effect])
        if key not in self.memo:
            model = self.base[:self.position] + [effect] + self.base[self.position:]
            self.memo[key] = self.ev.meter.residuals(self.ev.signals(model, split=self.position))
        return self.memo[key]

    def __call__(self, effect: KnobEffect) -> float:
        return float(np.sqrt(np.sum(self.residuals(effect) ** 2)))


def screen(ev: Evaluator, model: Sequence[KnobEffect], cand: Candidate,
           k_grid: Sequence[float] = K_GRID) -> FitResult:
    """Gap of ``model`` plus ``cand`` for each ``k`` of the grid (other parameters at defaults)."""
    pos = insert_position(model, cand.name)
    obj = _Objective(ev, model, pos)
    curve = [(float(k), obj(cand.template(k))) for k in k_grid]
    k, g = min(curve, key=lambda t: (t[1], t[0]))
    return FitResult(cand, cand.template(k), pos, g, 1, curve, len(curve))


def _fit_params(obj: _Objective, effect: KnobEffect, k_lo: float, k_hi: float, ev: Evaluator,
                extras_budget: int) -> tuple[KnobEffect, float, list[str]]:
    """Refine k by Brent in ``[k_lo, k_hi]``; extend k's range with the effect's scale parameter
    when k ends at 1; then k + the other live parameters by least squares (penalised)."""
    best_k, _ = _brent(lambda k: obj(_with(effect, k=k)), k_lo, k_hi, maxiter=8)
    effect = _with(effect, k=best_k)
    g_k = obj(effect)
    used: list[str] = []
    probe = int(np.argmax([float(im.std()) for im in ev.images[:4]])) if ev.images else 0
    live = live_params(effect, ev.images[probe], ev.depths[probe], ev.states[probe]) if ev.images else []
    scale = next((p for p in scale_params(effect.name) if p in live), None)
    if scale is not None and effect.k >= 0.98:
        lo, hi = type(effect).bounds_of(scale)
        us, _ = _brent(lambda u: obj(_with(effect, k=1.0, **{scale: _from_unit(u, lo, hi)})), 0.0, 1.0, maxiter=10)
        cand = _with(effect, k=1.0, **{scale: _from_unit(us, lo, hi)})
        if obj(cand) < g_k * (1.0 - PENALTY):
            effect, g_k, used = cand, obj(cand), [scale]
    extras = [p for p in live if p != scale]
    if not extras or extras_budget <= 0:
        return effect, g_k, used
    names = ["k"] + extras
    bounds = [type(effect).bounds_of(p) for p in names]
    u0 = np.array([_to_unit(float(getattr(effect, p)), lo, hi) for p, (lo, hi) in zip(names, bounds)])

    def at(u: np.ndarray) -> KnobEffect:
        return _with(effect, **{p: _from_unit(float(x), lo, hi) for p, x, (lo, hi) in zip(names, u, bounds)})

    starts = [u0]
    on_bound = (u0[1:] <= 1e-9) | (u0[1:] >= 1.0 - 1e-9)
    if on_bound.any():  # a default on its bound (e.g. exposure's flare = 0): also start inside
        u1 = u0.copy()
        u1[1:][on_bound] = np.where(u0[1:][on_bound] <= 1e-9, 0.25, 0.75)
        starts.append(u1)
    best: tuple[np.ndarray, float] | None = None
    for start in starts:
        u = _least_squares(lambda u: obj.residuals(at(u)), start, max_nfev=extras_budget + 6 * len(extras))
        g = obj(at(u))
        if best is None or g < best[1]:
            best = (u, g)
    u, g_x = best  # type: ignore[misc]  # starts is never empty
    moved = [p for p, a, b in zip(names[1:], u0[1:], u[1:]) if abs(a - b) > 0.02]
    if len(moved) < len(extras):  # extras that hardly moved keep their values
        u = np.array([x if p == "k" or p in moved else x0 for p, x, x0 in zip(names, u, u0)])
        g_x = obj(at(u))
    if g_x < g_k * (1.0 - PENALTY * len(moved)):
        return at(u), g_x, used + moved
    return effect, g_k, used


def fit(ev: Evaluator, model: Sequence[KnobEffect], screened: FitResult, *, extras_budget: int = 16) -> FitResult:
    """Refine a screened candidate: k between its grid neighbours, then the extra parameters."""
    grid = [k for k, _ in screened.curve]
    k0 = screened.effect.k
    i = grid.index(k0) if k0 in grid else 0
    lo = grid[i - 1] if i > 0 else 0.0
    hi = grid[i + 1] if i + 1 < len(grid) else 1.0
    obj = _Objective(ev, model, screened.position)
    obj.memo[_key([screened.effect])] = screened.fit_gap  # type: ignore[assignment]  # a gap where residuals go: obj() reads it right, obj.residuals() would not (reported)
    n0 = ev.n_evals
    effect, g, extras = _fit_params(obj, screened.effect, lo, hi, ev, extras_budget)
    return FitResult(screened.candidate, effect, screened.position, g, 1 + len(extras), screened.curve,
                     screened.n_evals + ev.n_evals - n0, extras)


def refit(ev: Evaluator, model: Sequence[KnobEffect], index: int, *, extras_budget: int = 10) -> FitResult:
    """Re-fit the parameters of ``model[index]`` with the rest of the model fixed."""
    effect = model[index]
    base = list(model[:index]) + list(model[index + 1:])
    obj = _Objective(ev, base, index)
    n0 = ev.n_evals
    g0 = obj(effect)
    grid = sorted({*K_GRID, effect.k})
    curve = [(k, obj(_with(effect, k=k))) for k in grid]
    kb, _ = min(curve, key=lambda t: (t[1], t[0]))
    i = grid.index(kb)
    lo, hi = (grid[i - 1] if i > 0 else 0.0), (grid[i + 1] if i + 1 < len(grid) else 1.0)
    new, g, extras = _fit_params(obj, effect, lo, hi, ev, extras_budget)
    if g >= g0:
        new, g, extras = effect, g0, []
    cand = Candidate(effect.name, tuple((p, getattr(effect, p)) for p in type(effect).CHOICES))
    return FitResult(cand, new, index, g, 1 + len(extras), curve, ev.n_evals - n0, extras)


def refit_joint(ev: Evaluator, model: Sequence[KnobEffect], *, budget: int | None = None) -> tuple[list[KnobEffect], float]:
    """Re-fit every effect of ``model`` together: bounded least squares over all their ``k`` and the
    extra parameters already moved from their defaults (effects that interact, e.g. ``dim`` and
    ``jpeg``, need a joint fit). Returns the new model and its gap on the fitting frames."""
    model = list(model)
    if not model:
        return model, ev.gap(model)
    slots: list[tuple[int, str, float, float]] = []
    for i, e in enumerate(model):
        defaults = {f.name: f.default for f in dataclasses.fields(e)}
        for p in ["k"] + [p for p in type(e).PARAM_BOUNDS if getattr(e, p) != defaults.get(p)]:
            lo, hi = type(e).bounds_of(p)
            slots.append((i, p, lo, hi))

    def build(u: np.ndarray) -> list[KnobEffect]:
        changes: dict[int, dict[str, float]] = {}
        for (i, p, lo, hi), x in zip(slots, u):
            changes.setdefault(i, {})[p] = _from_unit(float(x), lo, hi)
        return [_with(e, **changes[i]) if i in changes else e for i, e in enumerate(model)]

    memo: dict[tuple, np.ndarray] = {}

    def residuals(u: np.ndarray) -> np.ndarray:
        m = build(u)
        key = _key(m)
        if key not in memo:
            memo[key] = ev.meter.residuals(ev.signals(m))
        return memo[key]

    u0 = np.array([_to_unit(float(getattr(model[i], p)), lo, hi) for i, p, lo, hi in slots])
    g0 = float(np.linalg.norm(residuals(u0)))
    u = _least_squares(residuals, u0, max_nfev=budget or 10 + 6 * len(slots))
    g = float(np.linalg.norm(residuals(u)))
    return (build(u), g) if g < g0 else (model, g0)


def fit_summary(r: FitResult) -> dict[str, Any]:
    """JSON-friendly summary of a fit."""
    return {"candidate": r.candidate.describe(), "name": r.effect.name, "params": r.effect.params(),
            "position": r.position, "fit_gap": r.fit_gap, "n_params": r.n_params, "extras": r.extras,
            "n_evals": r.n_evals, "curve": [[k, g] for k, g in r.curve]}
