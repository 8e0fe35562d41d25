"""The defaults the docs quote are the code's: a changed default fails here until the page says it.

Three kinds of quotes are read from the pages themselves (so a new quote of the same kind is checked
without touching this file): a command option's ``(default N)``; the effects table of weather.md (each
effect's parameters and their defaults); a config class's ``Name`` defaults written as ``field = value``
on the line that names the class. The pages' tables of env arguments are checked against ``EnvConfig``.
"""

from __future__ import annotations

import dataclasses
import re
from fractions import Fraction
from pathlib import Path

import pytest

from weather_gym.agents.cone_shield import ConeShieldConfig
from weather_gym.cli import COMMANDS, build_parser
from weather_gym.envs.config import EnvConfig, RewardConfig
from weather_gym.sim.config import SimConfig
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.weather import EFFECTS, make

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
NUMBER = r"-?\d[\d,]*(?:\.\d+)?(?:/\d+)?"


def number(text: str) -> float:
    return float(Fraction(text.replace(",", "")))


def option_defaults() -> dict[str, set[str]]:
    """``--option`` -> the defaults it has across the sub-commands (as text)."""
    out: dict[str, set[str]] = {}
    root = build_parser()
    sub = next(a for a in root._actions if a.dest == "command")
    parsers = list(sub.choices.values())
    while parsers:
        p = parsers.pop()
        for action in p._actions:
            if hasattr(action, "choices") and isinstance(action.choices, dict):
                parsers += list(action.choices.values())  # nested sub-commands (dataset import ...)
            for flag in action.option_strings:
                out.setdefault(flag, set()).add(repr(action.default))
    return out


OPTION_QUOTE = re.compile(rf"`(--[a-z][a-z0-9-]*)[^`]*`[^`(]*?\(default ({NUMBER})\b")


def option_quotes() -> list[tuple[str, int, str, str]]:
    found = []
    for page in PAGES:
        for n, line in enumerate(page.read_text().splitlines(), 1):
            cells = line.strip("|").split("|")
            if line.startswith("|") and len(cells) > 1 and re.match(r"\s*`--", cells[0]):
                # a table row: its options (first cell) and the defaults quoted in the next one, in order
                options = re.findall(r"`(--[a-z][a-z0-9-]*)", cells[0])
                quotes = re.findall(rf"\(default ({NUMBER})\b", cells[1])
                if len(quotes) == 1 or len(quotes) == len(options):
                    found += [(page.name, n, o, q) for o, q in zip(options, quotes, strict=False)]
                continue
            for m in OPTION_QUOTE.finditer(line):
                found.append((page.name, n, m.group(1), m.group(2)))
    return found


def test_the_quote_finder_finds_quotes():
    assert OPTION_QUOTE.search("`--fit-frames` (default 32)").groups() == ("--fit-frames", "32")
    assert OPTION_QUOTE.search("`--pretrain-steps` env steps in all (default 60,000)").group(2) == "60,000"
    assert len(option_quotes()) >= 4 and len(COMMANDS) > 10


@pytest.mark.parametrize(("page", "line", "option", "quoted"), option_quotes())
def test_a_quoted_option_default_is_the_parser_default(page, line, option, quoted):
    defaults = option_defaults()
    assert option in defaults, f"{page}:{line}: {option} is an option of no command"
    values = {eval(d) for d in defaults[option]}  # noqa: S307 - reprs of argparse defaults
    assert any(isinstance(v, int | float) and not isinstance(v, bool) and v == number(quoted) for v in values), (
        f"{page}:{line}: {option} quoted with default {quoted}, the parsers have {sorted(map(str, values))}")


def effect_table_rows() -> list[tuple[str, str, str]]:
    """(effect, parameter, quoted default) from weather.md's table of effects."""
    rows = []
    text = (ROOT / "docs" / "weather.md").read_text()
    table = text[text.index("| name | what | k means | main parameters (defaults) |"):]
    for line in table.splitlines()[2:]:
        if not line.startswith("| `"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        name = cells[0].strip("`")
        for m in re.finditer(rf"`(\w+)` ({NUMBER}|true|false)(?![\w/])", cells[-1]):
            rows.append((name, m.group(1), m.group(2)))
    return rows


def test_the_effects_table_is_read():
    rows = effect_table_rows()
    assert {r[0] for r in rows} >= {"droplets", "dim", "noise", "fog", "jpeg"} and len(rows) >= 20


@pytest.mark.parametrize(("effect", "param", "quoted"), effect_table_rows())
def test_the_effects_table_quotes_each_effects_default(effect, param, quoted):
    assert effect in EFFECTS, f"weather.md names an effect {effect!r} the registry does not have"
    eff = make(effect, 0.0)
    assert hasattr(eff, param), f"weather.md: {effect} has no parameter {param!r}"
    value = getattr(eff, param)
    if quoted in ("true", "false"):
        assert value is (quoted == "true"), f"weather.md: {effect}.{param} quoted {quoted}, code {value!r}"
    else:
        assert value == pytest.approx(number(quoted)), f"weather.md: {effect}.{param} quoted {quoted}, code {value!r}"


CONFIGS = {"RewardConfig": RewardConfig, "EnvConfig": EnvConfig, "SimConfig": SimConfig, "LidarConfig": LidarConfig,
           "ConeShieldConfig": ConeShieldConfig}
FIELD_QUOTE = re.compile(rf"`(\w+) ?= ?({NUMBER}|True|False)`")


def config_quotes() -> list[tuple[str, int, str, str, str]]:
    """(page, paragraph, class, field, quoted) for ``field = value`` quotes in the sentence that starts
    with ``Class`` defaults (``with `RewardConfig` defaults `progress = 1.0`, ...``)."""
    found = []
    for page in PAGES:
        for n, para in enumerate(page.read_text().split("\n\n"), 1):
            for cls in CONFIGS:
                for start in re.finditer(rf"`{cls}` defaults", para):
                    sentence = re.split(r"\.\s|\(`", para[start.end():])[0]
                    found += [(page.name, n, cls, m.group(1), m.group(2)) for m in FIELD_QUOTE.finditer(sentence)
                              if m.group(1) in {f.name for f in dataclasses.fields(CONFIGS[cls])}]
    return found


def test_config_quotes_are_found():
    assert ("envs.md", "RewardConfig", "cone_hit") in {(p, c, f) for p, _, c, f, _ in config_quotes()}


@pytest.mark.parametrize(("page", "para", "cls", "field", "quoted"), config_quotes())
def test_a_quoted_config_default_is_the_dataclass_default(page, para, cls, field, quoted):
    value = getattr(CONFIGS[cls](), field)
    expected = {"True": True, "False": False}.get(quoted, None)
    if expected is None:
        assert value == pytest.approx(number(quoted)), f"{page} (paragraph {para}): {cls}.{field} quoted {quoted}, code {value!r}"
    else:
        assert value is expected, f"{page} (paragraph {para}): {cls}.{field} quoted {quoted}, code {value!r}"


def env_argument_rows() -> list[tuple[str, str]]:
    """(field, quoted default) from envs.md's table of ``gym.make`` arguments, for EnvConfig fields."""
    text = (ROOT / "docs" / "envs.md").read_text()
    table = text[text.index("| argument | default | meaning |"):]
    fields = {f.name for f in dataclasses.fields(EnvConfig)}
    rows = []
    for line in table.splitlines()[2:]:
        if not line.startswith("|"):
            break
        names, default = [c.strip() for c in line.strip("|").split("|")][:2]
        keys = re.findall(r"`(\w+)`", names)
        values = [v.strip().strip("`") for v in default.split(",")]
        if len(keys) == len(values) and all(k in fields for k in keys):
            rows += [(k, v) for k, v in zip(keys, values, strict=True)
                     if re.fullmatch(rf"{NUMBER}|true|false|[a-z_]+", v)]
    return rows


def test_the_env_argument_table_is_read():
    assert {"laps", "terminate_off_track", "off_track_margin"} <= {k for k, _ in env_argument_rows()}


@pytest.mark.parametrize(("field", "quoted"), env_argument_rows())
def test_the_env_argument_table_quotes_envconfig_defaults(field, quoted):
    value = getattr(EnvConfig(), field)
    if quoted in ("true", "false"):
        assert value is (quoted == "true"), f"envs.md: {field} quoted {quoted}, EnvConfig has {value!r}"
    elif re.fullmatch(NUMBER, quoted):
        assert value == pytest.approx(number(quoted)), f"envs.md: {field} quoted {quoted}, EnvConfig has {value!r}"
    else:
        assert str(value) == quoted, f"envs.md: {field} quoted {quoted}, EnvConfig has {value!r}"
