"""JSON Schema of the scenario TOML files (``envs/*.toml``), for editors and other tools.

Generated from the declarations the loader itself checks against: the top-level keys, the ``[env]``
keys (``EnvConfig``'s own fields and the time limit), one table per configuration section with its
dataclass's fields and types (pydantic's ``TypeAdapter(...).json_schema()``), the ``[weather]`` keys
with the preset conditions and severities, and ``[perception]``. Keys are optional as in the files
(a missing key takes its default) and unknown keys are refused, as ``load_scenario`` refuses them.
The types, ranges and choices are the ones each configuration declares (:mod:`weather_gym.core.schema`);
what relates two fields (``near < far``, a size limit) is not in the schema: ``load_scenario`` still checks
it, naming the file.

The other files a user writes have one too (:data:`FILE_SCHEMAS`): a presets file
(:func:`~weather_gym.weather.presets.presets_schema`), a ``--camera-model`` file (``CameraModel``'s fields)
and a ``--randomize-ranges`` file (``RandomizeRanges``' fields). Write one where your editor finds it (a
TOML editor such as taplo reads ``#:schema ./scenario.schema.json`` at the top of a file)::

    python -m weather_gym.envs.scenario_schema > scenario.schema.json
    python -m weather_gym.envs.scenario_schema presets > presets.schema.json

Example:
    >>> from weather_gym.envs.scenario_schema import scenario_schema
    >>> schema = scenario_schema()
    >>> schema["required"], sorted(schema["properties"])[:4]
    (['id'], ['camera', 'camera_model', 'car', 'description'])
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from typing import Any

from pydantic import TypeAdapter

from weather_gym.camera.isp import CameraModel
from weather_gym.envs.config import EnvConfig
from weather_gym.envs.scenario import ENV_KEYS, SECTIONS
from weather_gym.sim.randomize import RandomizeRanges
from weather_gym.weather.presets import SEVERITIES, aliases, conditions, presets_schema

__all__ = ["FILE_SCHEMAS", "camera_model_schema", "randomize_schema", "scenario_schema"]

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


def _file(cls: type, title: str) -> dict[str, Any]:
    """A TOML file that holds some of ``cls``'s fields at its top level (every key optional)."""
    defs: dict[str, Any] = {}
    table = _table(cls, None, defs)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title, **table,
            **({"$defs": defs} if defs else {})}


def camera_model_schema() -> dict[str, Any]:
    """The JSON Schema of a ``--camera-model`` TOML file (``CameraModel``'s fields; the rest keep the default)."""
    return _file(CameraModel, "weather-gym camera model (--camera-model FILE.toml)")


def randomize_schema() -> dict[str, Any]:
    """The JSON Schema of a ``--randomize-ranges`` TOML file (``RandomizeRanges``' fields)."""
    return _file(RandomizeRanges, "weather-gym randomize ranges (--randomize-ranges FILE.toml)")


FILE_SCHEMAS: dict[str, Callable[[], dict[str, Any]]] = {
    "scenario": scenario_schema, "presets": presets_schema, "camera-model": camera_model_schema,
    "randomize": randomize_schema}
"""Each kind of file a user writes -> its JSON Schema (``python -m weather_gym.envs.scenario_schema KIND``)."""


if __name__ == "__main__":
    kind = sys.argv[1] if len(sys.argv) > 1 else "scenario"
    if kind not in FILE_SCHEMAS:
        sys.exit(f"error: unknown kind {kind!r}; valid kinds: {', '.join(FILE_SCHEMAS)}")
    print(json.dumps(FILE_SCHEMAS[kind](), indent=2))
