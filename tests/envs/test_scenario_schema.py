"""The JSON Schema of scenario files: every shipped scenario validates, and what the loader refuses the
schema refuses too (an unknown key, a wrong type, both time limits)."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib

import pytest

from weather_gym.envs.scenario import scenario_files
from weather_gym.envs.scenario_schema import scenario_schema

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
