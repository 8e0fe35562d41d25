"""Performance-vs-k curves: reading a sweep's tidy file, seed statistics, and inverting the curve.

A :class:`Curve` holds one effect's metric (mAP@0.5 by default) at each k for each seed. The
calibration reads off the k at which the curve meets a measured level (:func:`invert`):

* the **mean curve** over seeds is made monotone non-increasing first (pool-adjacent-violators,
  i.e. isotonic regression; a sweep's noise can make two neighbouring means swap), and the report
  says when that changed anything;
* the target is found by **linear interpolation** between the two grid points that bracket it (on a
  flat stretch, the smallest k that reaches it: the least severe effect that does);
* the **interval** for k comes from the seed spread: the same inversion of the band ``mean - sd`` gives
  the low end, of ``mean + sd`` the high end (sd over seeds, ddof 1). A deterministic effect (the
  faithful dim) has no seed spread, so its interval is a point;
* a target **outside what the effect reaches** (above the curve at the smallest k, or below it at the
  largest) is never clamped silently: the result has ``reachable=False``, k at the end of the range
  that comes closest, and a note saying how far off it is.

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.calibration.curve import invert
    >>> ks = np.array([0.0, 0.5, 1.0]); mean = np.array([0.8, 0.6, 0.4])
    >>> r = invert(ks, mean, 0.5)
    >>> round(r.k, 3), r.reachable
    (0.75, True)
    >>> r = invert(ks, mean, 0.1)
    >>> r.k, r.reachable, r.note
    (1.0, False, 'the effect cannot bring the metric down to 0.100: at k = 1 it is 0.400 (0.300 short)')
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.lab.calibration.sweep_effect import SweepEffect
from weather_gym.weather import EFFECTS

__all__ = ["Curve", "Inversion", "REQUIRED_COLUMNS", "effect_name", "invert", "load_curves", "monotone_decreasing"]

REQUIRED_COLUMNS = ("effect", "k", "seed")
"""Columns every curve file needs, besides the metric (``map50`` by default)."""


@dataclass
class Curve:
    """One effect's metric at each k (rows) for each seed (columns; NaN where a cell is missing)."""

    label: str
    ks: np.ndarray
    seeds: tuple[int, ...]
    values: np.ndarray  # (len(ks), len(seeds))
    metric: str = "map50"
    name: str = ""
    params: dict[str, Any] = field(default_factory=dict)
    dataset_id: str = ""
    model_id: str = ""
    source: str = ""
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # other metrics, mean over seeds per k

    @property
    def mean(self) -> np.ndarray:
        return np.nanmean(self.values, axis=1)

    @property
    def sd(self) -> np.ndarray:
        """Standard deviation over seeds (ddof 1; 0 with a single seed)."""
        n = np.sum(np.isfinite(self.values), axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            sd = np.nanstd(self.values, axis=1, ddof=1) if self.values.shape[1] > 1 else np.zeros(len(self.ks))
        return np.where(n > 1, np.nan_to_num(sd), 0.0)

    @property
    def ideal(self) -> float:
        """Mean metric at k = 0 (the clean set: our own 'ideal conditions')."""
        i = np.flatnonzero(np.isclose(self.ks, 0.0))
        if i.size == 0:
            raise InputError(f"curve {self.label!r} ({self.source}) has no k = 0 row: relative matching needs "
                             "the clean mAP; sweep from k = 0 (e.g. --k 0:1:0.05) or use absolute matching")
        return float(self.mean[i[0]])

    def scaled(self, relative: bool) -> tuple[np.ndarray, np.ndarray]:
        """``(mean, sd)`` in absolute units, or relative to :attr:`ideal`."""
        if not relative:
            return self.mean, self.sd
        ideal = self.ideal
        if not ideal > 0:
            raise InputError(f"curve {self.label!r}: the clean {self.metric} is {ideal:g}; relative matching needs it > 0")
        return self.mean / ideal, self.sd / ideal

    def at(self, k: float, relative: bool = False) -> float:
        """The mean curve linearly interpolated at ``k``."""
        mean, _ = self.scaled(relative)
        return float(np.interp(k, self.ks, mean))

    def table(self, k: float) -> dict[str, Any]:
        """The effect table (``{name, k, ...params}``) of this curve at ``k``."""

        return SweepEffect(self.name or self.label, dict(self.params)).table(k)


@dataclass
class Inversion:
    """The k at which a curve meets ``target``, its interval, and whether it is really reached."""

    target: float
    k: float
    k_interval: tuple[float, float]
    reachable: bool
    achieved: float  # the monotone mean curve at k
    note: str = ""
    monotonised: bool = False


def monotone_decreasing(y: Sequence[float] | np.ndarray) -> np.ndarray:
    """The closest non-increasing sequence in least squares (pool adjacent violators).

    Example:
        >>> monotone_decreasing([1.0, 0.8, 0.85, 0.5]).round(3).tolist()
        [1.0, 0.825, 0.825, 0.5]
    """
    blocks: list[list[float]] = []  # [sum, count]
    for v in np.asarray(y, dtype=np.float64):
        blocks.append([float(v), 1.0])
        while len(blocks) > 1 and blocks[-2][0] / blocks[-2][1] < blocks[-1][0] / blocks[-1][1]:
            s, c = blocks.pop()
            blocks[-1][0] += s
            blocks[-1][1] += c
    return np.concatenate([np.full(int(c), s / c) for s, c in blocks])


def _crossing(ks: np.ndarray, y: np.ndarray, target: float) -> float | None:
    """Smallest k where the non-increasing ``y`` falls to ``target`` (None if outside its range)."""
    if target > y[0] or target < y[-1]:
        return None
    if target == y[0]:
        return float(ks[0])
    for i in range(len(ks) - 1):
        hi, lo = y[i], y[i + 1]
        if lo <= target <= hi:
            if hi == lo:
                return float(ks[i])
            return float(ks[i] + (hi - target) / (hi - lo) * (ks[i + 1] - ks[i]))
    return float(ks[-1])  # pragma: no cover - unreachable for a non-increasing y


def invert(ks: Sequence[float] | np.ndarray, mean: Sequence[float] | np.ndarray, target: float,
           sd: Sequence[float] | np.ndarray | None = None,
           what: str = "the metric") -> Inversion:
    """Read the k at which the (monotonised) mean curve meets ``target``; interval from ``mean -/+ sd``."""
    ks = np.asarray(ks, dtype=np.float64)
    mean = np.asarray(mean, dtype=np.float64)
    if ks.ndim != 1 or ks.shape != mean.shape or len(ks) < 2:
        raise InputError(f"a curve needs at least two k values with one mean each, got {len(ks)} k and {mean.size} values")
    if np.any(np.diff(ks) <= 0):
        raise InputError("the k values of a curve must be increasing")
    if not np.all(np.isfinite(mean)):
        bad = ks[~np.isfinite(mean)]
        raise InputError(f"the curve has no value at k = {', '.join(f'{k:g}' for k in bad)}")
    if not math.isfinite(target):
        raise InputError(f"target must be a finite number, got {target!r}")
    sd = np.zeros_like(mean) if sd is None else np.nan_to_num(np.asarray(sd, dtype=np.float64))
    mono = monotone_decreasing(mean)
    monotonised = bool(np.max(np.abs(mono - mean)) > 1e-12)
    k = _crossing(ks, mono, target)
    notes = []
    if k is None:
        reachable = False
        if target > mono[0]:
            k = float(ks[0])
            notes.append(f"the target {target:.3f} is above {what} at k = {ks[0]:g} ({mono[0]:.3f}, "
                         f"{target - mono[0]:.3f} above): the effect only lowers it; k = {ks[0]:g} comes closest")
        else:
            k = float(ks[-1])
            notes.append(f"the effect cannot bring {what} down to {target:.3f}: at k = {ks[-1]:g} it is "
                         f"{mono[-1]:.3f} ({mono[-1] - target:.3f} short)")
        interval = (k, k)
    else:
        reachable = True
        lo = _crossing(ks, monotone_decreasing(mean - sd), target)
        hi = _crossing(ks, monotone_decreasing(mean + sd), target)
        k_lo = float(ks[0]) if lo is None else lo
        if hi is None:
            hi = float(ks[-1])
            notes.append(f"the seed band still lies above the target at k = {ks[-1]:g}: the interval is open there")
        interval = (min(k_lo, k), max(hi, k))
    achieved = float(np.interp(k, ks, mono))
    note = "; ".join(notes)
    return Inversion(target=float(target), k=k, k_interval=interval, reachable=reachable, achieved=achieved,
                     note=note, monotonised=monotonised)


# ---------------------------------------------------------------------------------------- reading
def effect_name(label: str) -> str:
    """The registered effect a curve label belongs to (``dim_physical`` -> ``dim``), or the label itself."""

    names = [n for n in EFFECTS.names() if label == n or label.startswith(n + "_")]
    return max(names, key=len) if names else label


def _read_rows(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    if not path.is_file():
        raise MissingInputError(f"curve file {path} not found (write one with `weather-gym sweep`)")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"curve file {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"curve file {path} is empty")
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    return list(reader.fieldnames or []), list(reader)


def _float(path: Path, lineno: int, col: str, text: str | None) -> float:
    try:
        return float(text)  # type: ignore[arg-type]  # None (a short row): TypeError, caught below
    except (TypeError, ValueError):
        raise InputError(f"{path}, row {lineno}: column {col!r} must be a number, got {text!r}") from None


def _row_values(path: Path, lineno: int, r: dict, metric: str, extra_cols: list[str]) -> tuple[float, int, dict]:
    """``(k, seed, {"v": metric, extra columns...})`` of one curve-file row, checked."""
    k = _float(path, lineno, "k", r.get("k"))
    if not 0.0 <= k <= 1.0:
        raise InputError(f"{path}, row {lineno}: k = {k:g} is outside [0, 1]")
    try:
        seed = int(r.get("seed") or "")
    except ValueError:
        raise InputError(f"{path}, row {lineno}: column 'seed' must be an integer, got {r.get('seed')!r}") from None
    v = _float(path, lineno, metric, r.get(metric))
    if math.isfinite(v) and not 0.0 <= v <= 1.0:
        raise InputError(f"{path}, row {lineno}: {metric} = {v:g} is outside [0, 1]")
    vals = {"v": v}
    for c in extra_cols:
        try:
            vals[c] = float(r.get(c) or "nan")
        except ValueError:
            vals[c] = math.nan
    return k, seed, vals


def _curve(path: Path, label: str, cells: dict[tuple[float, int], dict[str, Any]], meta: dict[str, set],
           metric: str, extra_cols: list[str]) -> Curve:
    """One label's rows as a :class:`Curve` (refused when they mix datasets, models or specs)."""
    for key in ("dataset_id", "model_id", "spec"):
        if len(meta[key]) > 1:
            raise InputError(
                f"curve file {path}: effect {label!r} mixes {len(meta[key])} values of {key} "
                f"({', '.join(sorted(meta[key]))}); a resumed sweep with a new model or dataset keeps the old rows - "
                f"choose one (--{key.replace('_', '-')}) or sweep into a fresh folder")
    ks = np.array(sorted({k for k, _ in cells}))
    seeds = tuple(sorted({s for _, s in cells}))
    values = np.full((len(ks), len(seeds)), np.nan)
    extra = {c: np.full((len(ks), len(seeds)), np.nan) for c in extra_cols}
    for (k, s), vals in cells.items():
        i, j = int(np.searchsorted(ks, k)), seeds.index(s)
        values[i, j] = vals["v"]
        for c in extra_cols:
            extra[c][i, j] = vals[c]
    keep = np.isfinite(values).any(axis=1)
    spec = next(iter(meta["spec"]), "") or "{}"
    try:
        params = json.loads(spec)
    except json.JSONDecodeError:
        raise InputError(f"curve file {path}: effect {label!r} has a 'spec' that is not JSON: {spec!r}") from None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns (a class absent from the set)
        extra_mean = {c: np.nanmean(a[keep], axis=1) for c, a in extra.items()}
    return Curve(label=label, ks=ks[keep], seeds=seeds, values=values[keep], metric=metric,
                 name=effect_name(label), params=params, dataset_id=next(iter(meta["dataset_id"]), ""),
                 model_id=next(iter(meta["model_id"]), ""), source=str(path), extra=extra_mean)


def load_curves(path: str | os.PathLike, *, metric: str = "map50", effect: str | None = None,
                dataset_id: str | None = None, model_id: str | None = None) -> dict[str, Curve]:
    """Read a curve file (``weather-gym sweep``'s ``curves.csv``) into one :class:`Curve` per effect label.

    Needs the columns ``effect``, ``k``, ``seed`` and ``metric``; ``status`` (only ``ok`` rows are
    used), ``spec``, ``dataset_id`` and ``model_id`` are used when present. A label whose rows come
    from several datasets or models is refused unless ``dataset_id`` / ``model_id`` pick one.
    ``k`` must lie in [0, 1] and the metric in [0, 1] (NaN allowed); errors name the file, row,
    column and value.
    """
    path = Path(path)
    header, rows = _read_rows(path)
    missing = [c for c in (*REQUIRED_COLUMNS, metric) if c not in header]
    if missing:
        raise InputError(f"curve file {path} lacks column(s) {', '.join(missing)}; expected at least "
                         f"{', '.join((*REQUIRED_COLUMNS, metric))} (as written by `weather-gym sweep`); "
                         f"it has: {', '.join(header) or '(no header)'}")
    extra_cols = [c for c in header if c.startswith(("recall", "ap50_")) or c == "map"]
    wanted = {key: want for key, want in (("dataset_id", dataset_id), ("model_id", model_id))
              if want is not None and key in header}
    data: dict[str, dict[tuple[float, int], dict[str, Any]]] = {}
    info: dict[str, dict[str, set]] = {}
    for lineno, r in enumerate(rows, start=2):
        if "status" in header and r.get("status") != "ok":
            continue
        label = (r.get("effect") or "").strip()
        if not label:
            raise InputError(f"{path}, row {lineno}: empty 'effect'")
        if (effect is not None and label != effect) or any(r.get(key) != want for key, want in wanted.items()):
            continue
        k, seed, vals = _row_values(path, lineno, r, metric, extra_cols)
        data.setdefault(label, {})[(k, seed)] = vals
        meta = info.setdefault(label, {"spec": set(), "dataset_id": set(), "model_id": set()})
        for key in meta:
            if key in header:
                meta[key].add(r.get(key) or "")
    if not data:
        what = f" for effect {effect!r}" if effect else ""
        raise InputError(f"curve file {path} has no usable (status ok) rows{what}")
    return {label: _curve(path, label, cells, info[label], metric, extra_cols) for label, cells in data.items()}
