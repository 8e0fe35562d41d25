"""Weather presets: a condition and a severity 0-4 name a list of effects (``presets.toml``).

Every registered effect is a condition (``rain@2``, ``fog@3``, ...; its ``CONDITION``, by default its
name): the study's two, ``droplets`` and ``low_light`` (alias ``dim``), then the others by name. Each
row says whether it is **calibrated** (its k was read off a measured perception drop by ``weather-gym
calibrate``; ``calibrated = true``) or **nominal** (a documented choice of k, not measured;
``calibrated = false``). The presets file holds the calibrated rows; the nominal ones are the effect's
own, generated from what its class declares (``NOMINAL_K``, default k = severity / 4, and
``NOMINAL_NOUN``) for every condition the file has no row for. The table ships with the package
(``weather_gym/weather/presets.toml``); calibration rewrites the rows it measured, keeps the others,
and nothing else changes.

File format: free top-level metadata, then one ``[[presets]]`` table per condition and severity with
``condition``, ``severity``, ``effects`` (a list of ``{name, k, ...}`` tables as in model files),
``calibrated`` (bool; default: the file's top-level ``calibrated``, else false) and optional fields
(``description``, ``k_interval``, ``measured_map``, ``measured_relative``, ``achieved_relative``,
``note``, anything else) kept as they are. A condition in the file has all five severities (they
replace its nominal rows); a file need not hold every condition.

Example:
    >>> from weather_gym.weather.presets import conditions, nominal_rows, preset_entry, preset_spec
    >>> conditions()[:3]
    ('droplets', 'low_light', 'blur')
    >>> preset_spec("droplets", 3)[0]["name"]
    'droplets'
    >>> preset_spec("dim", 0)            # "dim" is an alias of low_light; severity 0 is clear
    []
    >>> preset_entry("rain", 2)["calibrated"], preset_spec("rain", 2)
    (False, [{'name': 'rain', 'k': 0.5}])
    >>> nominal_rows("glare")[3]["description"]
    'Nominal heavy sun glare'
"""

from __future__ import annotations

import copy
import numbers
import os
import tomllib
from pathlib import Path
from typing import Any

from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.weather.registry import EFFECTS
from weather_gym.weather.tables import effect_from_table, effect_table_schema

__all__ = ["DEFAULT_PRESETS", "PRESETS_ENV", "SEVERITIES", "STUDY_CONDITIONS", "aliases",
           "canonical_condition", "conditions", "load_presets", "nominal_rows", "preset_entry", "preset_source",
           "preset_spec", "presets_meaning", "presets_path", "presets_schema"]

#: The reference study's conditions (its Table 2), listed first.
STUDY_CONDITIONS = ("droplets", "low_light")
SEVERITIES = (0, 1, 2, 3, 4)
#: The shipped table.
DEFAULT_PRESETS = Path(__file__).with_name("presets.toml")

#: Environment variable that switches what ``CONDITION@SEVERITY`` means when no presets file is given:
#: unset or ``resolved`` - resolved for the scenario where one is known (an env, ``lap``, ``evaluate``,
#: ``degrade --reference``; docs/calibration.md), the shipped pool presets where none is (a bare
#: ``parse_weather``, a ``WeatherWrapper`` around another env); ``pool`` - the shipped pool presets
#: everywhere; a presets file (e.g. one ``weather-gym calibrate --track`` resolved) - that file everywhere.
PRESETS_ENV = "WEATHER_GYM_PRESETS"
#: The values of :data:`PRESETS_ENV` that name a meaning, not a file.
PRESETS_MEANINGS = ("resolved", "pool")

_NOMINAL_NOTE = "nominal: k = severity / 4 over the effect's designed range [0, 1]; not measured"
_NOMINAL_WORDS = ("", "light", "moderate", "heavy", "severe")


def conditions() -> tuple[str, ...]:
    """Every condition: the study's two, then the other registered effects' conditions by name."""
    found = {cls.condition() for cls in (EFFECTS.get(n) for n in EFFECTS)}
    study = tuple(c for c in STUDY_CONDITIONS if c in found)
    return study + tuple(sorted(found - set(study)))


def aliases() -> dict[str, str]:
    """Other names accepted for a condition: the name of each effect whose condition is not its name."""
    return {n: EFFECTS.get(n).condition() for n in EFFECTS if EFFECTS.get(n).condition() != n}


def __getattr__(name: str) -> Any:
    """``CONDITIONS`` (:func:`conditions`) and ``ALIASES`` (:func:`aliases`), read from the registry
    when asked, so an effect registered later is in them."""
    if name == "CONDITIONS":
        return conditions()
    if name == "ALIASES":
        return aliases()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def nominal_rows(condition: str) -> dict[int, dict[str, Any]]:
    """The nominal ``[[presets]]`` rows of a condition, ``{severity: table}``, from its effect's
    ``NOMINAL_K`` and ``NOMINAL_NOUN``; ``{}`` when its effect declares none (calibrated rows only)."""
    cond = canonical_condition(condition)
    cls = next(EFFECTS.get(n) for n in EFFECTS if EFFECTS.get(n).condition() == cond)
    if cls.NOMINAL_K is None:
        return {}
    noun = cls.NOMINAL_NOUN or cls.name.replace("_", " ")
    ks = (0.0, *cls.NOMINAL_K)
    note = _NOMINAL_NOTE if tuple(cls.NOMINAL_K) == (0.25, 0.5, 0.75, 1.0) else \
        f"nominal: k = {', '.join(f'{k:g}' for k in cls.NOMINAL_K)} at severities 1-4, declared by the effect; not measured"
    return {s: {"condition": cond, "severity": s, "calibrated": False,
                "description": f"Nominal {_NOMINAL_WORDS[s]} {noun}" if s else "No effect",
                "effects": [{"name": cls.name, "k": float(ks[s])}] if s else [], "note": note}
            for s in SEVERITIES}


_CACHE: dict[tuple[str, int], dict[str, Any]] = {}


def presets_path(path: str | os.PathLike | None = None) -> Path:
    """The presets file in use: ``path``, else ``$WEATHER_GYM_PRESETS`` (a file), else the shipped pool presets
    (this layer knows no scenario to resolve for: the env and the commands resolve, see :func:`presets_meaning`)."""
    if path is not None:
        return Path(path)
    env = os.environ.get(PRESETS_ENV, "").strip()
    return DEFAULT_PRESETS if env in ("", *PRESETS_MEANINGS) else Path(env)


def presets_meaning() -> str:
    """What ``CONDITION@SEVERITY`` means where no presets file is given, from ``$WEATHER_GYM_PRESETS``:
    ``"resolved"`` (unset or ``resolved``: the default), ``"pool"``, or ``"file"`` (it names a file).

    Example:
        >>> presets_meaning() in ("resolved", "pool", "file")
        True
    """
    env = os.environ.get(PRESETS_ENV, "").strip()
    return "resolved" if env in ("", "resolved") else "pool" if env == "pool" else "file"


def preset_source(path: str | os.PathLike | None = None) -> str:
    """Where a preset's k comes from with ``path`` (see :func:`presets_path`): ``"pool"`` (the shipped
    presets, calibrated on the pool of tracks), ``"resolved"`` (a file resolved for one scenario,
    ``k_source = "resolved"``) or ``"file"`` (another presets file).

    Example:
        >>> preset_source(DEFAULT_PRESETS)
        'pool'
    """
    p = presets_path(path)
    if p.resolve() == DEFAULT_PRESETS.resolve():
        return "pool"
    src = load_presets(p).get("k_source")
    return src if src in ("resolved", "pool") else "file"


def canonical_condition(condition: str) -> str:
    """``condition`` or its alias as one of :func:`conditions`; ValueError listing them otherwise."""
    known, alias = conditions(), aliases()
    if isinstance(condition, str):
        c = alias.get(condition, condition)
        if c in known:
            return c
    raise InputError(f"unknown weather condition {condition!r}; valid conditions: {', '.join(known)} "
                     f"(aliases: {', '.join(f'{a}={c}' for a, c in alias.items())})")


def _check_severity(severity: Any) -> int:
    if isinstance(severity, bool) or not isinstance(severity, numbers.Integral) or int(severity) not in SEVERITIES:
        raise InputError(f"invalid severity {severity!r}; valid severities: {', '.join(map(str, SEVERITIES))}")
    return int(severity)


def _validate(data: dict[str, Any], path: Path) -> dict[str, Any]:
    tables = data.get("presets")
    if not isinstance(tables, list):
        raise FileFormatError(f"{path}: expected [[presets]] tables")
    default_calibrated = data.get("calibrated", False)
    if not isinstance(default_calibrated, bool):
        raise FileFormatError(f"{path}: 'calibrated' must be true or false")
    out: dict[str, dict[int, dict[str, Any]]] = {c: {} for c in conditions()}
    for i, t in enumerate(tables):
        where = f"{path}: [[presets]] #{i + 1}"
        if not isinstance(t, dict):
            raise FileFormatError(f"{where}: expected a table")
        for key in ("condition", "severity", "effects"):
            if key not in t:
                raise FileFormatError(f"{where}: missing key {key!r}")
        try:
            cond = canonical_condition(t["condition"])
            sev = _check_severity(t["severity"])
            if not isinstance(t["effects"], list):
                raise FileFormatError(f"effects must be a list of {{name, k, ...}} tables, got {t['effects']!r}")
            for e in t["effects"]:
                effect_from_table(e)
        except ValueError as exc:
            raise FileFormatError(f"{where}: {exc}") from None
        if sev in out[cond]:
            raise FileFormatError(f"{where}: {cond} severity {sev} appears twice")
        t = dict(t)
        t.setdefault("calibrated", default_calibrated)
        if not isinstance(t["calibrated"], bool):
            raise FileFormatError(f"{where}: 'calibrated' must be true or false, got {t['calibrated']!r}")
        out[cond][sev] = t
    out = {c: sevs for c, sevs in out.items() if sevs}
    for cond, sevs in out.items():
        missing = [s for s in SEVERITIES if s not in sevs]
        if missing:
            raise FileFormatError(f"{path}: condition {cond!r} has no preset for severity {missing}")
    if not out:
        raise FileFormatError(f"{path}: no [[presets]] tables")
    meta = {k: v for k, v in data.items() if k not in ("presets", "calibrated")}
    calibrated = tuple(c for c, sevs in out.items() if all(t["calibrated"] for t in sevs.values()))
    return {**meta, "calibrated": bool(calibrated), "calibrated_conditions": calibrated, "presets": out}


def presets_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a presets file: ``[[presets]]`` rows of a condition (or an alias), a
    severity 0-4 and a list of effect tables (:func:`~weather_gym.weather.tables.effect_table_schema`), each
    with an optional ``calibrated`` flag; every other key (a row's description and measured numbers, the
    file's provenance) is free. What the schema cannot say (one row per condition and severity, all five
    severities of a condition) :func:`load_presets` checks.

    Example:
        >>> presets_schema()["properties"]["presets"]["items"]["required"]
        ['condition', 'severity', 'effects']
    """
    row = {"type": "object", "properties": {
        "condition": {"enum": [*conditions(), *aliases()]},
        "severity": {"type": "integer", "enum": list(SEVERITIES)},
        "effects": {"type": "array", "items": effect_table_schema()},
        "calibrated": {"type": "boolean"}},
        "required": ["condition", "severity", "effects"]}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "weather-gym presets file",
            "type": "object", "properties": {"presets": {"type": "array", "items": row, "minItems": 1},
                                             "calibrated": {"type": "boolean"}},
            "required": ["presets"]}


def load_presets(path: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """Read and validate a presets file (default: the shipped one).

    Returns ``{<top-level keys>, "presets": {condition: {severity: table}}, "calibrated_conditions":
    (conditions whose every row is calibrated), "calibrated": bool(calibrated_conditions)}``; every
    table has its ``calibrated`` flag. The conditions the file has no rows for get their effect's
    nominal rows (:func:`nominal_rows`). Re-read whenever the file changes.
    """
    p = presets_path(path)
    if not p.is_file():
        env = os.environ.get(PRESETS_ENV, "").strip() if path is None else ""
        raise MissingInputError(f"presets file {p} not found" + (f" (from ${PRESETS_ENV})" if env else ""))
    key = (str(p.resolve()), p.stat().st_mtime_ns)
    if key not in _CACHE:
        try:
            with p.open("rb") as f:
                data = tomllib.load(f)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:  # a TOML file is UTF-8 text
            raise FileFormatError(f"{p}: not valid TOML: {exc}") from None
        _CACHE[key] = _validate(data, p)
    out = copy.deepcopy(_CACHE[key])
    in_file = out["presets"]
    out["presets"] = {c: in_file[c] if c in in_file else nominal_rows(c) for c in conditions()}
    out["presets"] = {c: rows for c, rows in out["presets"].items() if rows}
    return out


def preset_entry(condition: str, severity: int, path: str | Path | None = None) -> dict[str, Any]:
    """The whole ``[[presets]]`` table of a condition and severity (effects, measurements, ...)."""
    cond, sev = canonical_condition(condition), _check_severity(severity)
    table = load_presets(path)["presets"]
    if cond not in table:
        raise InputError(f"presets file {presets_path(path)} has no rows for condition {cond!r} "
                         f"(it has: {', '.join(table)})")
    entry: dict[str, Any] = table[cond][sev]
    return entry


def preset_spec(condition: str, severity: int, path: str | Path | None = None) -> list[dict[str, Any]]:
    """The effect list (``[{"name": ..., "k": ..., ...}]``) of a condition and severity."""
    effects: list[dict[str, Any]] = preset_entry(condition, severity, path)["effects"]
    return effects
