"""``--presets pool|resolved|FILE``: what each value gives, and the errors."""

from __future__ import annotations

import pytest

from weather_gym.cli import build_parser
from weather_gym.cli._presets_arg import env_scenario, presets_from_arg
from weather_gym.core.errors import FileFormatError, MissingInputError, ResolutionError
from weather_gym.weather.presets import DEFAULT_PRESETS


def test_values(tmp_path):
    assert presets_from_arg(None, None) is None
    assert presets_from_arg("pool", None) == DEFAULT_PRESETS
    with pytest.raises(MissingInputError, match="--presets: .*nope.toml not found"):
        presets_from_arg(str(tmp_path / "nope.toml"), None)
    bad = tmp_path / "bad.toml"
    bad.write_text("x = 1\n")
    with pytest.raises(FileFormatError, match=r"\[\[presets\]\]"):
        presets_from_arg(str(bad), None)
    with pytest.raises(ResolutionError, match="needs a scenario"):
        presets_from_arg("resolved", None)


def test_every_weather_command_takes_it():
    p = build_parser()
    assert p.parse_args(["lap", "--presets", "resolved"]).presets == "resolved"
    assert p.parse_args(["degrade", "a", "b", "--presets", "pool"]).presets == "pool"
    assert p.parse_args(["evaluate", "--out", "o", "--presets", "f.toml"]).presets == "f.toml"


def test_env_scenario_is_the_runs_scenario():
    sc = env_scenario("WeatherGym/ConeTrack-v0", "skidpad", None, {"camera": {"width": 336, "height": 188}})
    assert sc.tracks == ("skidpad",) and sc.camera.width == 336 and sc.scene == "plain"
