"""Measured perception levels to calibrate against: a CSV table, or labelled measured image sets.

**Table** (like the study's ``paper_table2_measured_map.csv``): ``#`` comment lines, then a header
with ``condition``, ``severity`` and at least one of ``map`` and ``relative_to_ideal`` (alias
``relative``); optional ``domain`` (default ``measured``) and ``description``. ``condition`` is
``ideal`` (severity 0: the clear reference of its domain) or a weather condition (``droplets``,
``low_light``, or an alias such as ``dim``). A missing ``relative_to_ideal`` is ``map / map of the
ideal row of the same domain``; when both are given they must agree to within 0.01.

**Measured image sets**: folders in the project's COCO layout (``weather-gym dataset``), labelled by
hand, scored by the detector here. ``CONDITION@SEVERITY=DIR`` makes the whole folder one level
(``droplets@3=data/real_heavy_drops``), ``ideal=DIR`` the clear reference; a bare ``DIR`` is split by
the ``condition`` / ``severity`` fields of its image records.

Example:
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> _ = p.write_text("condition,domain,severity,map\\nideal,real,0,0.8\\ndroplets,real,2,0.6\\n")
    >>> [(m.condition, m.severity, round(m.relative, 3)) for m in read_measured_table(p)]
    [('ideal', 0, 1.0), ('droplets', 2, 0.75)]
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.lab.datasets import load_coco
from weather_gym.perception import score_detections
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.scoring import small_rule
from weather_gym.weather.presets import SEVERITIES, aliases, canonical_condition, conditions

__all__ = ["IDEAL", "MeasuredLevel", "levels_by_condition", "load_measured", "measure_datasets",
           "parse_measured_arg", "read_measured_table"]

IDEAL = "ideal"
_IDEAL_ALIASES = ("ideal", "clear", "none")
_REL_COLUMNS = ("relative_to_ideal", "relative")


@dataclass(frozen=True)
class MeasuredLevel:
    """One measured level: condition (``ideal`` or a canonical weather condition) x severity x domain."""

    condition: str
    severity: int
    domain: str
    map: float  # NaN when only the relative value was given
    relative: float  # map / the domain's ideal map (NaN when unknown)
    description: str = ""
    source: str = ""
    images: int | None = None


def _condition(text: str, where: str) -> str:
    t = (text or "").strip()
    if t.lower() in _IDEAL_ALIASES:
        return IDEAL
    try:
        return canonical_condition(t)
    except ValueError:
        alias = ", ".join(f"{a} = {c}" for a, c in aliases().items())
        raise InputError(f"{where}: unknown condition {t!r}; valid: ideal, {', '.join(conditions())} "
                         f"(aliases: {alias})") from None


def _severity(text: str, where: str) -> int:
    try:
        s = int(str(text).strip())
    except ValueError:
        raise InputError(f"{where}: severity must be an integer 0-4, got {text!r}") from None
    if s not in SEVERITIES:
        raise InputError(f"{where}: severity {s} is outside 0-4")
    return s


def _number(text: str | None, where: str, col: str, lo: float, hi: float) -> float:
    if text is None or str(text).strip() == "":
        return math.nan
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{where}: column {col!r} must be a number, got {text!r}") from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise InputError(f"{where}: {col} = {text} is outside [{lo:g}, {hi:g}]")
    return v


def _fill_relative(levels: list[MeasuredLevel], where: str) -> list[MeasuredLevel]:
    """Relative values from the ideal of each domain; check given ones against map / ideal."""
    ideals = {m.domain: m for m in levels if m.condition == IDEAL}
    out = []
    for m in levels:
        ideal = ideals.get(m.domain)
        ideal_map = ideal.map if ideal is not None else math.nan
        if m.condition == IDEAL:
            out.append(replace(m, relative=1.0 if math.isnan(m.relative) else m.relative))
            continue
        derived = m.map / ideal_map if math.isfinite(m.map) and math.isfinite(ideal_map) and ideal_map > 0 else math.nan
        if math.isnan(m.relative):
            out.append(replace(m, relative=derived))
        else:
            if math.isfinite(derived) and abs(derived - m.relative) > 0.01:
                raise InputError(f"{where}: {m.condition} severity {m.severity} ({m.domain}): relative_to_ideal "
                                 f"{m.relative:g} disagrees with map / ideal map = {m.map:g} / {ideal_map:g} = "
                                 f"{derived:.3f}")
            out.append(m)
    return out


def read_measured_table(path: str | os.PathLike) -> list[MeasuredLevel]:
    """Read and validate a measured-levels CSV (see the module doc); errors name file, row and column."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"measured table {path} not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"measured table {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"measured table {path} is empty")
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    header = [h.strip() for h in reader.fieldnames or []]
    reader.fieldnames = header
    missing = [c for c in ("condition", "severity") if c not in header]
    rel_col = next((c for c in _REL_COLUMNS if c in header), None)
    if "map" not in header and rel_col is None:
        missing.append("map or relative_to_ideal")
    if missing:
        raise InputError(f"measured table {path} lacks column(s) {', '.join(missing)}; it has: {', '.join(header)}")
    levels: list[MeasuredLevel] = []
    seen: dict[tuple, int] = {}
    for lineno, row in enumerate(reader, start=2):
        where = f"{path}, data row {lineno - 1}"
        cond = _condition(row.get("condition", ""), where)
        sev = _severity(row.get("severity", ""), where)
        if cond == IDEAL and sev != 0:
            raise InputError(f"{where}: the ideal (clear) row must have severity 0, got {sev}")
        domain = (row.get("domain") or "measured").strip() or "measured"
        mp = _number(row.get("map"), where, "map", 0.0, 1.0)
        rel = _number(row.get(rel_col) if rel_col else None, where, rel_col or "relative_to_ideal", 0.0, 10.0)
        if math.isnan(mp) and math.isnan(rel):
            raise InputError(f"{where}: {cond} severity {sev} has neither map nor relative_to_ideal")
        key = (cond, sev, domain)
        if key in seen:
            raise InputError(f"{where}: {cond} severity {sev} ({domain}) already given in data row {seen[key]}")
        seen[key] = lineno - 1
        images = row.get("images")
        levels.append(MeasuredLevel(cond, sev, domain, mp, rel, (row.get("description") or "").strip(), str(path),
                                    int(images) if images and images.strip().isdigit() else None))
    return _fill_relative(levels, str(path))


# ------------------------------------------------------------------------------------ image sets
def parse_measured_arg(text: str) -> tuple[str, Any]:
    """``--measured`` value -> ``("table", path)`` or ``("dataset", (condition|None, severity|None, path))``."""
    text = str(text)
    if "=" in text and not Path(text).exists():
        label, _, folder = text.partition("=")
        label = label.strip()
        if label.lower() in _IDEAL_ALIASES:
            return "dataset", (IDEAL, 0, Path(folder))
        cond, at, sev = label.partition("@")
        if not at:
            raise InputError(f"--measured {text!r}: expected CONDITION@SEVERITY=DIR (e.g. droplets@3=data/drops3), "
                             "ideal=DIR, a COCO folder or a CSV table")
        where = f"--measured {text!r}"
        return "dataset", (_condition(cond, where), _severity(sev, where), Path(folder))
    p = Path(text)
    if p.is_dir():
        return "dataset", (None, None, p)
    if p.is_file():
        return "table", p
    raise MissingInputError(f"--measured {text}: no such file or folder (expected a CSV table, a COCO folder, "
                            "CONDITION@SEVERITY=DIR or ideal=DIR)")


def measure_datasets(items: Sequence[tuple[str | None, int | None, Path]], model: Any = None,
                     *, domain: str = "measured", progress: bool = True) -> list[MeasuredLevel]:
    """Score the detector (a spec or detector, see ``weather_gym.perception.load_detector``) on labelled
    measured image sets; one level per (condition, severity) group. Ignore masks and ignore regions of
    the sets apply; the too-small rule is the detector's."""

    det = load_detector(model)
    rules: dict[tuple[str, int], Any] = {}
    groups: dict[tuple[str, int], list[tuple[dict, Any]]] = {}
    sources: dict[tuple[str, int], list[str]] = {}
    for cond, sev, folder in items:
        ds = load_coco(folder)
        frames: list[tuple[dict, tuple[str, int]]] = []
        for i in range(len(ds)):
            if cond is not None:
                key = (cond, int(sev))  # type: ignore[arg-type]  # given with cond
            else:
                rec = ds.record(i)
                where = f"{folder}: image {rec.get('file_name', i)}"
                if "condition" not in rec or "severity" not in rec:
                    raise InputError(f"{where} has no 'condition'/'severity' fields; label the whole folder with "
                                     f"--measured CONDITION@SEVERITY={folder} (or ideal={folder})")
                c = _condition(str(rec["condition"]), where)
                key = (c, 0 if c == IDEAL else _severity(rec["severity"], where))
            frames.append((ds.gt(i), key))
            rule = small_rule(ds, det)
            if rule is None or rules.setdefault(key, rule).min_height_px != rule.min_height_px:
                raise InputError(f"{folder}: frames of one level must have one size (the too-small rule depends "
                                 "on it); import each camera size into its own folder")

        dets = []
        for start in tqdm(range(0, len(ds), 8), desc=f"measure {Path(folder).name}", unit="batch",
                          disable=not progress):
            ims = [ds.image(i) for i in range(start, min(len(ds), start + 8))]
            dets += det.detect_batch(ims, score_threshold=0.05)
        for (gt, key), d in zip(frames, dets, strict=True):
            groups.setdefault(key, []).append((gt, d))
            sources.setdefault(key, [])
            if str(folder) not in sources[key]:
                sources[key].append(str(folder))
    levels = []
    for (cond, sev), pairs in sorted(groups.items()):
        rule = rules[(cond, sev)]
        r = score_detections([g for g, _ in pairs], [d for _, d in pairs], score_threshold=det.score_threshold,
                             min_box_height=rule.min_height_px, too_small=rule.describe())
        if not math.isfinite(r.map50):
            raise InputError(f"measured set {', '.join(sources[cond, sev])} ({cond} severity {sev}) has no scorable cones")
        levels.append(MeasuredLevel(cond, sev, domain, float(r.map50), math.nan,
                                    f"measured: {len(pairs)} images, {r.n_gt} cones", "; ".join(sources[cond, sev]),
                                    len(pairs)))
    return _fill_relative(levels, "measured image sets")


def load_measured(values: Sequence[str], model: Any = None,
                  progress: bool = True) -> list[MeasuredLevel]:
    """All ``--measured`` values (tables and image sets) -> levels."""
    levels: list[MeasuredLevel] = []
    sets = []
    for v in values:
        kind, what = parse_measured_arg(v)
        if kind == "table":
            levels += read_measured_table(what)
        else:
            sets.append(what)
    if sets:
        levels += measure_datasets(sets, model, progress=progress)
    return levels


def levels_by_condition(levels: Sequence[MeasuredLevel], *, domain: str | None = None,
                        match: str = "relative") -> tuple[dict[str, dict[int, MeasuredLevel]], MeasuredLevel | None, str]:
    """Pick one domain: ``({condition: {severity: level}}, its ideal level or None, domain)``.

    Without ``domain`` the domain of the weather rows is used when there is exactly one. Relative
    matching needs every chosen level's relative value (an ideal row of that domain, or the column).
    """
    weather = [m for m in levels if m.condition != IDEAL]
    if not weather:
        raise InputError("the measured levels hold no weather condition (only ideal rows): nothing to calibrate")
    domains = sorted({m.domain for m in weather})
    if domain is None:
        if len(domains) > 1:
            raise InputError(f"the measured levels come from several domains ({', '.join(domains)}); pick one with --domain")
        domain = domains[0]
    elif domain not in domains:
        raise InputError(f"--domain {domain!r}: no weather rows in that domain; domains: {', '.join(domains)}")
    out: dict[str, dict[int, MeasuredLevel]] = {}
    for m in weather:
        if m.domain != domain:
            continue
        value = m.relative if match == "relative" else m.map
        if not math.isfinite(value):
            need = ("relative_to_ideal, or an ideal row (condition ideal, severity 0) of domain "
                    f"{domain!r}") if match == "relative" else "map"
            raise InputError(f"{m.source}: {m.condition} severity {m.severity} has no {match} value for "
                             f"{match} matching: give {need}")
        out.setdefault(m.condition, {})[m.severity] = m
    ideal = next((m for m in levels if m.condition == IDEAL and m.domain == domain), None)
    return out, ideal, domain
