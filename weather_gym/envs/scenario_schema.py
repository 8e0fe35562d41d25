"""JSON Schema of the scenario TOML files (``envs/*.toml``), for editors and other tools.

Generated from the declarations the loader itself checks against: the top-level keys, the ``[env]``
keys (``EnvConfig``'s own fields and the time limit), one table per configuration section with its
dataclass's fields and types (pydantic's ``TypeAdapter(...).json_schema()``), the ``[weather]`` keys
with the preset conditions and severities, and ``[perception]``. Keys are optional as in the files
(a missing key takes its default) and unknown keys are refused, as ``load_scenario`` refuses them.
Ranges that a configuration checks in code (``CameraConfig``'s image size, ...) are not in the schema:
``load_scenario`` still checks them, naming the file.

Write it where your editor finds it (a TOML editor such as taplo reads ``#:schema ./scenario.schema.json``
at the top of a file)::

    python -m weather_gym.envs.scenario_schema > scenario.schema.json

Example:
    >>> from weather_gym.envs.scenario_schema import scenario_schema
    >>> schema = scenario_schema()
    >>> schema["required"], sorted(schema["properties"])[:4]
    (['id'], ['camera', 'camera_model', 'car', 'description'])
"""

from __future__ import annotations

import json
from typing import Any

from pydantic import TypeAdapter

from weather_gym.envs.config import EnvConfig
from weather_gym.envs.scenario import ENV_KEYS, SECTIONS
from weather_gym.weather.presets import SEVERITIES, aliases, conditions

__all__ = ["scenario_schema"]

SCHEMA_ID = "https://weather-gym.invalid/scenario.schema.json"


def _table(cls: type, keys: tuple[str, ...] | None, defs: dict[str, Any]) -> dict[str, Any]:
    """The schema of a TOML table of ``cls``'s fields (only ``keys`` when given): every key optional."""
    schema = TypeAdapter(cls).json_schema(ref_template="#/$defs/{model}")
    defs.update(schema.pop("$defs", {}))
    props = schema.get("properties", {})
    if keys is not None:
        props = {k: v for k, v in props.items() if k in keys}
    return {"type": "object", "description": (cls.__doc__ or cls.__name__).strip().splitlines()[0],
            "properties": props, "additionalProperties": False}


def scenario_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scenario file, as a dict (``json.dumps`` it to save it)."""
    defs: dict[str, Any] = {}
    env = _table(EnvConfig, ENV_KEYS, defs)
    env["properties"]["max_episode_s"] = {"type": "number", "exclusiveMinimum": 0,
                                          "description": "time limit in simulated seconds (default 100)"}
    env["properties"]["max_episode_steps"] = {"type": "integer", "minimum": 1,
                                              "description": "time limit in steps at the scenario's control rate"}
    env["not"] = {"required": ["max_episode_s", "max_episode_steps"]}  # one of them at most
    weather = {
        "type": "object", "description": "spec = any weather spec, or condition and severity (a preset)",
        "properties": {
            "spec": {"description": "a weather spec: 'droplets@3', 'dim:0.5', a list of {name, k, ...} tables",
                     "type": ["string", "array", "object"]},
            "condition": {"enum": [*conditions(), *aliases()]},
            "severity": {"type": "integer", "enum": list(SEVERITIES)},
        },
        "additionalProperties": False,
        "not": {"anyOf": [{"required": ["spec", "condition"]}, {"required": ["spec", "severity"]}]},
        "dependentRequired": {"severity": ["condition"]},
    }
    perception = {
        "type": "object", "description": "mode (a perception mode), detector (a detector spec) and the "
                                         "perception wrapper's keyword arguments",
        "properties": {"mode": {"type": "string"}, "detector": {"type": "string"}},
        "additionalProperties": True,
    }
    properties: dict[str, Any] = {
        "id": {"type": "string", "pattern": r"^[^/]+/.+-v[0-9]+$",
               "description": "the Gymnasium id, like 'WeatherGym/Name-v0'"},
        "description": {"type": "string"},
        "env": env,
        **{name: _table(cls, None, defs) for name, cls in SECTIONS.items()},
        "weather": weather,
        "perception": perception,
    }
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID,
            "title": "weather-gym scenario (envs/*.toml)", "type": "object", "required": ["id"],
            "properties": properties, "additionalProperties": False, "$defs": defs}


if __name__ == "__main__":
    print(json.dumps(scenario_schema(), indent=2))
