"""Calibration: the k of each effect whose perception drop matches a measured severity, and presets.

The study's method (Fursa et al., Sections 3.5 and 4): sweep k, measure the detector's mAP at each k,
and read off the k whose mAP matches the mAP measured in real weather of a given severity.

**Relative matching (default).** Our detector, training data and renderer are not the study's: our
clean mAP on our evaluation set is not its 0.793 (real) or 0.715 (simulated). Matching absolute
levels would ask our detector for numbers that have nothing to do with the weather (the study's
"very light droplets" level 0.796 lies above our clean mAP; its own simulator sat a constant
7-8 points below its real camera at every k). What carries over between detectors and domains is
the *drop*: mAP in the weather / mAP in ideal conditions of the same domain. So by default a
severity's target is ``measured map / measured ideal map`` and our curve is divided by its own clean
value (k = 0). ``match="absolute"`` matches the mAP values themselves (when the measured set and the
sweep use the same detector and domain, e.g. real images of the same track scored by this model).

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.calibration.curve import Curve
    >>> from weather_gym.lab.calibration.measured import MeasuredLevel
    >>> from weather_gym.lab.calibration.calibrate import calibrate
    >>> ks = np.linspace(0, 1, 5)
    >>> curve = Curve("droplets", ks, (0,), (0.8 - 0.4 * ks)[:, None], name="droplets")
    >>> lv = [MeasuredLevel("ideal", 0, "real", 0.8, 1.0), MeasuredLevel("droplets", 2, "real", 0.6, 0.75)]
    >>> out = calibrate({"droplets": curve}, lv)
    >>> [(c.severity, round(c.k, 3), c.reachable) for c in out]
    [(0, 0.0, True), (2, 0.5, True)]
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._toml import toml_document
from weather_gym.core.errors import InputError
from weather_gym.lab.calibration.curve import Curve, invert
from weather_gym.lab.calibration.measured import MeasuredLevel, levels_by_condition
from weather_gym.lab.calibration.sweep import (
    KEY_FIELDS,
    SweepEffect,
    make_sweep_cells,
    metric_by_cell,
    run_sweep_cell,
)
from weather_gym.lab.evaluation.runner import run_cells
from weather_gym.weather.presets import (
    SEVERITIES,
    canonical_condition,
    conditions,
    load_presets,
    nominal_rows,
)

__all__ = ["DEFAULT_USE", "MATCHES", "PresetCalibration", "calibrate", "parse_use", "remeasure",
           "write_presets"]

MATCHES = ("relative", "absolute")
DEFAULT_USE = {"droplets": "droplets", "low_light": "dim"}
"""Condition -> curve label used for it by default (low_light: the faithful dim)."""
K_DECIMALS = 3


@dataclass
class PresetCalibration:
    """One calibrated preset (a condition and severity) and how it was obtained."""

    condition: str
    severity: int
    description: str
    curve: str  # the label of the curve used for the condition
    effects: list[dict[str, Any]]
    k: float
    k_interval: tuple[float, float]
    reachable: bool
    match: str
    target: float  # the value matched (relative or absolute)
    measured_map: float
    measured_relative: float
    predicted: float  # the mean curve at k, in the matched units
    k_other: float = math.nan  # k from the other matching mode, for comparison
    note: str = ""
    monotonised: bool = False
    achieved_map: float = math.nan
    achieved_relative: float = math.nan
    achieved_sd: float = math.nan  # sd over seeds of the re-measured relative value
    achieved_source: str = ""
    domain: str = ""

    @property
    def achieved(self) -> float:
        """The achieved value in the matched units (re-measured when available)."""
        return self.achieved_relative if self.match == "relative" else self.achieved_map

    def toml_fields(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "condition": self.condition, "severity": self.severity, "calibrated": True,
            "description": self.description,
            "effects": self.effects, "k_interval": list(self.k_interval), "measured_map": self.measured_map,
            "measured_relative": self.measured_relative, "achieved_map": self.achieved_map,
            "achieved_relative": self.achieved_relative,
        }
        if self.severity > 0:
            out.update(achieved_sd=self.achieved_sd, target=self.match, reachable=self.reachable,
                       curve=self.curve, predicted=self.predicted)
            out[f"k_{'absolute' if self.match == 'relative' else 'relative'}"] = self.k_other
        out["note"] = self.note
        return out


def parse_use(values: Sequence[str] | None) -> dict[str, str]:
    """``["low_light=dim_physical"]`` -> the condition -> curve mapping (defaults filled in)."""

    use = dict(DEFAULT_USE)
    for v in values or []:
        cond, eq, label = str(v).partition("=")
        if not eq or not label.strip():
            raise InputError(f"--use {v!r}: expected CONDITION=CURVE_LABEL, e.g. low_light=dim_physical")
        use[canonical_condition(cond.strip())] = label.strip()
    return use


def _round_k(k: float) -> float:
    return float(round(k, K_DECIMALS))


def _round_interval(lo: float, hi: float) -> tuple[float, float]:
    """``(lo, hi)`` rounded outward to ``K_DECIMALS``: the stored interval contains the exact one, so an
    interval narrower than the rounding of k does not read as zero width (a point stays a point)."""
    if hi <= lo:
        return _round_k(lo), _round_k(lo)
    scale = 10 ** K_DECIMALS
    return (float(math.floor(lo * scale + 1e-9) / scale), float(math.ceil(hi * scale - 1e-9) / scale))


def calibrate(curves: Mapping[str, Curve], levels: Sequence[MeasuredLevel], *, match: str = "relative",
              use: Mapping[str, str] | None = None, domain: str | None = None,
              descriptions: Mapping[tuple[str, int], str] | None = None) -> list[PresetCalibration]:
    """Invert each condition's curve at each measured severity (and add severity 0 = no effect)."""
    if match not in MATCHES:
        raise InputError(f"unknown match {match!r}; valid: {', '.join(MATCHES)}")
    use = dict(DEFAULT_USE if use is None else use)
    by_cond, ideal, domain = levels_by_condition(levels, domain=domain, match=match)
    descriptions = descriptions or {}
    out: list[PresetCalibration] = []
    for cond in sorted(by_cond):
        label = use.get(cond, cond)
        if label not in curves:
            raise InputError(f"condition {cond!r} is calibrated with the curve {label!r} (change with --use "
                             f"{cond}=LABEL), but the curve files hold: {', '.join(sorted(curves))}")
        curve = curves[label]
        mean, sd = curve.scaled(relative=(match == "relative"))
        other_mean, other_sd = curve.scaled(relative=(match != "relative"))
        what = "our relative mAP" if match == "relative" else "our mAP"
        ideal_map = ideal.map if ideal is not None else math.nan
        out.append(PresetCalibration(
            condition=cond, severity=0, description=descriptions.get((cond, 0), "Clear"), curve=label, effects=[],
            k=0.0, k_interval=(0.0, 0.0), reachable=True, match=match, target=1.0 if match == "relative" else ideal_map,
            measured_map=ideal_map, measured_relative=1.0, predicted=1.0 if match == "relative" else curve.ideal,
            achieved_map=curve.ideal if 0.0 in curve.ks else math.nan, achieved_relative=1.0,
            achieved_sd=0.0, achieved_source="no effect", domain=domain))
        for sev in sorted(by_cond[cond]):
            m = by_cond[cond][sev]
            target = m.relative if match == "relative" else m.map
            inv = invert(curve.ks, mean, target, sd, what=what)
            other_target = m.map if match == "relative" else m.relative
            k_other = math.nan  # the other matching mode's k (NaN: no value, or out of reach)
            if math.isfinite(other_target):
                other = invert(curve.ks, other_mean, other_target, other_sd)
                k_other = other.k if other.reachable else math.nan
            note = inv.note
            if inv.monotonised:
                note = "; ".join(filter(None, [note, "the mean curve was not monotone: inverted its isotonic fit"]))
            k = _round_k(inv.k)
            out.append(PresetCalibration(
                condition=cond, severity=sev, description=descriptions.get((cond, sev)) or m.description,
                curve=label, effects=[curve.table(k)], k=k,
                k_interval=_round_interval(*inv.k_interval), reachable=inv.reachable,
                match=match, target=float(target), measured_map=m.map, measured_relative=m.relative,
                predicted=float(inv.achieved), k_other=_round_k(k_other) if math.isfinite(k_other) else math.nan,
                note=note, monotonised=inv.monotonised, domain=domain))
    return out


# ------------------------------------------------------------------------------------- re-measuring
def remeasure(calibs: Sequence[PresetCalibration], curves: Mapping[str, Curve], dataset: str | os.PathLike,
              results_path: str | os.PathLike, *, seeds: Sequence[int] = (0, 1, 2, 3, 4),
              model: Any = None, workers: int | None = None, backend: str = "process",
              ray_address: str | None = None, progress: bool = True,
              metric: str = "map50") -> list[dict[str, Any]]:
    """Measure each preset's effect at its chosen k (and k = 0) on ``dataset`` over ``seeds``.

    Fills ``achieved_map``, ``achieved_relative`` (mean over seeds of mAP at k / mean mAP at k = 0 on the
    same set) and ``achieved_sd`` in place; rows go to ``results_path`` through the evaluation runner
    (resumable). Returns the rows.
    """

    wanted: dict[str, set[float]] = {}
    for c in calibs:
        wanted.setdefault(c.curve, {0.0}).add(c.k)
    cells = []
    for label, ks in wanted.items():
        cv = curves[label]
        eff = SweepEffect(cv.name or label, dict(cv.params))
        cells += make_sweep_cells([eff], sorted(ks), seeds, dataset, model)
    rows = run_cells(cells, run_sweep_cell, results_path, key_fields=KEY_FIELDS, workers=workers,
                     backend=backend, ray_address=ray_address, progress=progress, desc="re-measure")
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        raise RuntimeError(f"{len(failed)} re-measurement cell(s) failed, e.g. {failed[0]['error']} "
                           f"(see {results_path}; run again to retry)")
    by = {(label, k): v for (_, label, k), v in metric_by_cell(cells, rows, metric).items()}  # one dataset
    for c in calibs:
        vals = np.array(by[(c.curve, c.k)])
        clean = float(np.mean(by[(c.curve, 0.0)]))
        c.achieved_map = float(np.mean(vals))
        c.achieved_relative = c.achieved_map / clean if clean > 0 else math.nan
        c.achieved_sd = float(np.std(vals / clean, ddof=1)) if len(vals) > 1 and clean > 0 else 0.0
        c.achieved_source = f"re-measured: {len(vals)} seeds on {Path(dataset).name}"
    return rows


def fill_from_curves(calibs: Sequence[PresetCalibration], curves: Mapping[str, Curve]) -> None:
    """Without a re-measurement: achieved values interpolated from the mean curves (marked as such)."""
    for c in calibs:
        cv = curves[c.curve]
        c.achieved_map = cv.at(c.k)
        c.achieved_relative = cv.at(c.k, relative=True)
        _, sd = cv.scaled(True)
        c.achieved_sd = float(np.interp(c.k, cv.ks, sd))
        c.achieved_source = "interpolated from the curve (not re-measured)"


# ------------------------------------------------------------------------------------------- TOML
def _copied_row(row: Mapping[str, Any], base: str | os.PathLike | None) -> dict[str, Any]:
    """A base row not measured in this run: nominal rows as they are; calibrated ones marked as not."""
    row = dict(row)
    was_calibrated = row.pop("calibrated", False)
    fields = {k: row.pop(k) for k in ("condition", "severity")}
    fields["calibrated"] = False
    fields.update(row)
    if was_calibrated:
        fields["note"] = (f"not calibrated here (no measured level): copied from "
                          f"{Path(base).name if base else 'the shipped presets.toml'}")
    return fields


def _effect_text(effect: Mapping[str, Any]) -> str:
    """An effect table without its k in the ``--effect`` grammar of ``weather-gym sweep`` (for a comment)."""
    params = ",".join(f"{k}={v}" for k, v in effect.items() if k != "name")
    return f"{effect['name']}:{params}" if params else str(effect["name"])


HEADER = """\
# weather-gym weather presets: condition x severity (0-4) -> list of effects.
#
# Rows with calibrated = true were CALIBRATED with `weather-gym calibrate` (weather_gym/lab/calibration/,
# docs/calibration.md), the reference study's method: sweep k, measure the shipped detector's mAP@0.5 on a
# fixed rendered evaluation set at each k (5 weather realisations per k), and read off the k where that curve
# meets the level measured in real weather of the severity. Conditions and severities are the study's
# (Table 2): real-world "droplets" on the lens and "low_light" (late afternoon .. night).
# Rows with calibrated = false are NOMINAL: a documented choice of k (see their note), not measured. Every
# effect has such rows, so that "rain@2" works: those its class declares (NOMINAL_K, default k = severity / 4)
# are generated on load and not written here; a row here replaces them. Calibration keeps them as they are.
#
# match = "relative": what is matched is the DROP, mAP in the weather / mAP in ideal conditions of the same
# domain (the study's real camera: 0.793; our detector on our clean set: eval_ideal_map), because our
# detector is not the study's. k_absolute is what matching the absolute mAP would have given (nan: that
# level is out of the effect's reach with our detector).
#
# Each calibrated [[presets]] table: condition, severity, calibrated, description, effects = [{ name = ...,
# k = ..., <params> }], k_interval = [lo, hi] (k where mean -/+ 1 sd over seeds meets the target, rounded outward),
# measured_map / measured_relative (the study's measurement), achieved_map / achieved_relative / achieved_sd
# (our detector re-measured at the chosen k, mean and sd over seeds), predicted (the mean curve at k),
# reachable = false when the effect cannot reach the target at any k in [0, 1] (then k is the end of the
# range that comes closest and note says by how much; nothing is clamped silently).
"""


def write_presets(calibs: Sequence[PresetCalibration], path: str | os.PathLike, *, meta: Mapping[str, Any],
                  base: str | os.PathLike | None = None, overwrite: bool = False, header: str = HEADER) -> Path:
    """Write a presets TOML (``weather_gym.weather.presets`` format), validated by ``load_presets`` first.

    The calibrated rows get ``calibrated = true``. Every other condition x severity of ``base``
    (default: the shipped table) is copied with ``calibrated = false``: a nominal row as it is (an
    effect's own generated nominal rows are not written: they are generated on load), a row calibrated
    before (not measured in this run) with a note saying so. ``path`` is never overwritten
    unless ``overwrite``.
    """

    path = check_output(path, overwrite=overwrite, suffixes=(".toml",))
    done = {(c.condition, c.severity): c for c in calibs}
    base_tables = load_presets(base)["presets"]
    lines = [header.rstrip("\n")]
    used: dict[str, tuple[str, dict[str, Any]]] = {}
    for c in calibs:
        if c.severity > 0 and c.effects:
            used.setdefault(c.condition, (c.curve, {k: v for k, v in c.effects[0].items() if k != "k"}))
    if used:
        lines.append("#")
        for cond, (curve, eff) in sorted(used.items()):
            lines.append(f"# {cond}: curve {curve!r}, effect {_effect_text(eff)} with the k below.")
    lines.append("")
    rows = []
    for cond in conditions():
        if not any((cond, s) in done for s in SEVERITIES) and cond not in base_tables:
            continue
        if not any((cond, s) in done for s in SEVERITIES) and base_tables[cond] == nominal_rows(cond):
            continue  # its effect's own nominal rows: generated on load, not written
        for sev in SEVERITIES:
            if (cond, sev) in done:
                rows.append(done[cond, sev].toml_fields())
            elif cond not in base_tables:
                raise InputError(f"condition {cond!r}: severity {sev} was not calibrated and the base presets "
                                 f"have no row for it")
            else:
                rows.append(_copied_row(base_tables[cond][sev], base))
    document = {k: v for k, v in meta.items() if k not in ("calibrated", "calibrated_conditions")}
    # floats to 4 decimals, NaN and infinities as TOML's nan/inf, None as ""
    text = "\n".join(lines) + "\n" + toml_document({**document, "presets": rows}, digits=4, none="")
    # the loader's own validation: a file it would refuse is never written
    return atomic_write(path, text, check=load_presets, overwrite=overwrite)

