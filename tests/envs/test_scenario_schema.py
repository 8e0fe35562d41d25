"""The JSON Schemas of the files a user writes (scenarios, presets, camera models, randomize ranges): every
shipped file validates, and what the reader refuses the schema refuses too (an unknown key, a wrong type, a
value out of its declared range, both time limits)."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from weather_gym.envs.scenario import scenario_files
from weather_gym.envs.scenario_schema import FILE_SCHEMAS, scenario_schema

jsonschema = pytest.importorskip("jsonschema")  # the dev extra


@pytest.fixture(scope="module")
def validator():
    schema = scenario_schema()
    jsonschema.Draft202012Validator.check_schema(schema)  # a valid draft 2020-12 schema
    return jsonschema.Draft202012Validator(schema)


def test_every_shipped_scenario_validates(validator):
    files = scenario_files()
    assert len(files) >= 6
    for path in files:
        with path.open("rb") as f:
            errors = [e.message for e in validator.iter_errors(tomllib.load(f))]
        assert not errors, (path.name, errors)


@pytest.mark.parametrize("doc", [
    {"id": "WeatherGym/X-v0", "camera": {"widht": 336}},                      # a typo'd key
    {"id": "WeatherGym/X-v0", "camera": {"width": "wide"}},                   # a wrong type
    {"id": "WeatherGym/X-v0", "env": {"max_episode_s": 10.0, "max_episode_steps": 300}},  # both limits
    {"id": "WeatherGym/X-v0", "weather": {"condition": "snow"}},              # an unknown condition
    {"id": "WeatherGym/X-v0", "weather": {"spec": "rain@2", "severity": 2}},  # spec and severity
    {"id": "not an id"},
    {"description": "no id"},
    {"id": "WeatherGym/X-v0", "detector": {}},                                # an unknown table
])
def test_what_the_loader_refuses_the_schema_refuses(validator, doc):
    assert list(validator.iter_errors(doc))


def test_the_schema_is_written_by_its_module(tmp_path):
    done = subprocess.run([sys.executable, "-m", "weather_gym.envs.scenario_schema"], capture_output=True,
                          text=True, timeout=120, check=True)
    assert json.loads(done.stdout) == scenario_schema()


@pytest.mark.parametrize("doc", [
    {"id": "WeatherGym/X-v0", "camera": {"width": 0}},                        # out of its declared range
    {"id": "WeatherGym/X-v0", "env": {"random_start": 2.0}},
    {"id": "WeatherGym/X-v0", "sim": {"renderer": "vulkan"}},                 # not one of the choices
])
def test_the_declared_ranges_are_in_the_schema(validator, doc):
    assert list(validator.iter_errors(doc))


ROOT = Path(__file__).resolve().parents[2]
SHIPPED = {  # every file of each kind the project ships (docs included)
    "presets": ["weather_gym/weather/presets.toml", "weather_gym/lab/calibration/presets_physical.toml",
                "tests/weather/data/presets_uncalibrated.toml", "docs/calibration/resolved/*.toml",
                "docs/calibration/resolved_yolov8/*/*.toml"],
    "camera-model": ["docs/calibration/no_*.toml"],
}


@pytest.mark.parametrize("kind", sorted(SHIPPED))
def test_every_shipped_file_of_a_kind_validates(kind):
    schema = FILE_SCHEMAS[kind]()
    jsonschema.Draft202012Validator.check_schema(schema)
    check = jsonschema.Draft202012Validator(schema)
    files = [p for pattern in SHIPPED[kind] for p in sorted(ROOT.glob(pattern))]
    assert len(files) >= len(SHIPPED[kind])
    for path in files:
        with path.open("rb") as f:
            errors = [e.message for e in check.iter_errors(tomllib.load(f))]
        assert not errors, (path.name, errors)


@pytest.mark.parametrize("kind, doc", [
    ("presets", {"presets": [{"condition": "snowstorm", "severity": 1, "effects": []}]}),
    ("presets", {"presets": [{"condition": "rain", "severity": 1, "effects": [{"name": "dim", "k": 2.0}]}]}),
    ("presets", {"presets": [{"condition": "rain", "severity": 1, "effects": [{"name": "dim", "k": 0.5, "gain": 1}]}]}),
    ("camera-model", {"jpeg_quality": 101}),
    ("camera-model", {"white_balance": [1.0, 1.0]}),
    ("randomize", {"k1": [-1.0, 0.0]}),
    ("randomize", {"p_ego": 1.5}),
    ("randomize", {"sun_elevation": [10.0, 20.0]}),
])
def test_what_the_readers_refuse_the_file_schemas_refuse(kind, doc):
    schema = FILE_SCHEMAS[kind]()
    jsonschema.Draft202012Validator.check_schema(schema)
    assert list(jsonschema.Draft202012Validator(schema).iter_errors(doc))


def test_a_bad_value_in_a_file_names_the_file_key_value_and_range(tmp_path):
    from weather_gym.core.errors import FileFormatError
    from weather_gym.envs.scenario import load_scenario
    from weather_gym.sim.randomize import RandomizeRanges

    bad = tmp_path / "bad.toml"
    bad.write_text('id = "WeatherGym/Bad-v0"\n[camera]\nhfov_deg = 200.0\n')
    with pytest.raises(FileFormatError, match=r"bad.toml: CameraConfig.hfov_deg must be a finite number in "
                                               r"\[1, 170\], got 200.0"):
        load_scenario(bad)
    ranges = tmp_path / "ranges.toml"
    ranges.write_text("k1 = [0.2, 0.1]\n")
    with pytest.raises(FileFormatError, match=r"ranges.toml: randomize.k1: \(0.2, 0.1\) must satisfy "
                                               r"-0.3 <= low <= high <= 0.3"):
        RandomizeRanges.from_toml(ranges)


@pytest.mark.parametrize("kind", ["presets", "camera-model", "randomize"])
def test_each_file_schema_is_written_by_the_module(kind):
    done = subprocess.run([sys.executable, "-m", "weather_gym.envs.scenario_schema", kind], capture_output=True,
                          text=True, timeout=120, check=True)
    assert json.loads(done.stdout) == FILE_SCHEMAS[kind]()
