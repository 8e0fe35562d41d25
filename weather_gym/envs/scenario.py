"""Declarative scenarios: TOML files in ``envs/`` describing track, car, camera, sim, weather, perception.

A scenario file::

    id = "WeatherGym/ConeTrack-v0"
    description = "..."
    [env]         # EnvConfig fields (track, laps, camera_images, ground_truth, ...) and the time limit:
                  # max_episode_s (simulated seconds; the TimeLimit is max_episode_s * control_hz steps)
                  # or max_episode_steps (steps at the scenario's control_hz), not both
    [sim]         # SimConfig fields
    [car]         # CarConfig fields
    [camera]      # CameraConfig fields
    [odometry]    # OdometryConfig fields
    [reward]      # RewardConfig fields
    [camera_model]  # CameraModel fields (weather_gym.camera.isp); no table: the default realistic camera;
                    # keys change single fields of it; enabled = false: the study's ideal camera (off)
    [weather]     # optional: spec = "droplets@2" (any weather spec), or condition/severity
    [perception]  # optional: mode = "detector" (see weather_gym.pipeline.PERCEPTION_MODES),
                  # detector = "model.onnx", and the perception wrapper's keyword arguments

Example:
    >>> from weather_gym.envs.scenario import load_scenario, scenario_files
    >>> sc = load_scenario(scenario_files()[0])
    >>> sc.env_id.startswith("WeatherGym/")
    True
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel
from weather_gym.core._io import resolve_inside
from weather_gym.core._toml import read_toml
from weather_gym.core.errors import FileFormatError, InputError, check_known
from weather_gym.core.paths import data_dir
from weather_gym.envs.config import EnvConfig, RewardConfig
from weather_gym.sim.config import CarConfig, OdometryConfig, SimConfig
from weather_gym.tracks import track_file_part
from weather_gym.weather import parse_weather

SECTIONS: dict[str, type] = {
    "sim": SimConfig,
    "car": CarConfig,
    "camera": CameraConfig,
    "odometry": OdometryConfig,
    "reward": RewardConfig,
    "camera_model": CameraModel,
}
ENV_KEYS = tuple(f.name for f in fields(EnvConfig) if f.name not in SECTIONS)
TOP_KEYS = ("id", "description", "env", "weather", "perception", *SECTIONS)
DEFAULT_MAX_EPISODE_S = 100.0
"""The time limit of a scenario that gives none: 100 s of simulated time (3000 steps at 30 Hz)."""


@dataclass(frozen=True)
class Scenario:
    """A parsed scenario file."""

    env_id: str
    path: str
    description: str = ""
    env: dict[str, Any] = field(default_factory=dict)
    sections: dict[str, dict[str, Any]] = field(default_factory=dict)
    weather: dict[str, Any] | None = None
    perception: dict[str, Any] | None = None
    max_episode_s: float = DEFAULT_MAX_EPISODE_S

    @property
    def control_hz(self) -> float:
        """The scenario's control rate (its ``[sim] control_hz``, else ``SimConfig``'s default)."""
        return float(self.sections.get("sim", {}).get("control_hz", SimConfig().control_hz))

    @property
    def max_episode_steps(self) -> int:
        """The ``TimeLimit`` the id is registered with: ``max_episode_s`` at the scenario's control rate."""
        return episode_steps(self.max_episode_s, self.control_hz)


def episode_steps(max_episode_s: float, control_hz: float) -> int:
    """Steps of a ``max_episode_s`` time limit at ``control_hz`` (at least 1).

    Example:
        >>> episode_steps(100.0, 30.0), episode_steps(100.0, 60.0)
        (3000, 6000)
    """
    return max(1, int(round(float(max_episode_s) * float(control_hz))))


def scenario_files() -> list[Path]:
    """The shipped scenario files, sorted."""
    return sorted(data_dir("envs").glob("*.toml"))


def load_scenario(path: str | Path) -> Scenario:
    """Parse and validate a scenario TOML file; errors name the file and the key."""
    path = Path(path)
    data = read_toml(path, "scenario file")
    if "detector" in data:
        raise FileFormatError(f"{path}: the [detector] table is now [perception] with mode = \"detector\" "
                              "(and the DetectorWrapper keyword arguments)")
    check_known(data, TOP_KEYS, what=str(path))
    env_id = data.get("id")
    if not isinstance(env_id, str) or "/" not in env_id or not env_id.rsplit("-v", 1)[-1].isdigit():
        raise FileFormatError(f"{path}: 'id' must be a Gymnasium id like 'WeatherGym/Name-v0', got {env_id!r}")
    env = data.get("env", {})
    if not isinstance(env, dict):
        raise FileFormatError(f"{path}: [env] must be a table of EnvConfig fields, got {env!r}")
    env = dict(env)
    check_known(env, (*ENV_KEYS, "max_episode_steps", "max_episode_s"), what=f"{path} [env]")
    max_steps, max_s = _pop_time_limit(path, env)
    env = _confine_paths(path, env, "env", "track")
    sections = {}
    for name, cls in SECTIONS.items():
        sec = data.get(name, {})
        if not isinstance(sec, dict):
            raise FileFormatError(f"{path}: [{name}] must be a table")
        check_known(sec, {f.name for f in fields(cls)}, what=f"{path} [{name}]")
        sections[name] = sec
    weather = data.get("weather")
    if weather is not None:
        if not isinstance(weather, dict):
            raise FileFormatError(f"{path}: [weather] must be a table (spec = ..., or condition and severity)")
        check_known(weather, ("spec", "condition", "severity"), what=f"{path} [weather]")
        _check_weather(path, weather)
    perception = data.get("perception")
    if perception is not None:
        if not isinstance(perception, dict) or not isinstance(perception.get("mode", "camera"), str):
            raise FileFormatError(f"{path}: [perception] must be a table with mode = \"camera\" | \"detector\" | "
                                  "\"oracle\" | \"gt_cones\" and the perception wrapper's arguments")
        perception = _confine_detector(path, perception)
    sc = Scenario(env_id=env_id, path=str(path), description=str(data.get("description", "")), env=env,
                  sections=sections, weather=weather, perception=perception)
    try:  # build once so that bad values fail at load time, naming the file (any other error is a bug)
        build_config(sc)
    except InputError as exc:
        raise FileFormatError(f"{path}: {exc}") from None
    if max_steps is not None:  # steps at the scenario's own control rate: the same seconds at any other
        sc = dataclasses.replace(sc, max_episode_s=max_steps / sc.control_hz)
    elif max_s is not None:
        sc = dataclasses.replace(sc, max_episode_s=float(max_s))
    return sc


def _pop_time_limit(path: Path, env: dict[str, Any]) -> tuple[Any, Any]:
    """Pop and check ``max_episode_steps`` / ``max_episode_s`` from an [env] table (at most one)."""
    max_steps = env.pop("max_episode_steps", None)
    max_s = env.pop("max_episode_s", None)
    if max_steps is not None and max_s is not None:
        raise FileFormatError(f"{path} [env]: give max_episode_s or max_episode_steps, not both")
    if max_steps is not None and (isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1):
        raise FileFormatError(f"{path} [env]: max_episode_steps must be an integer >= 1, got {max_steps!r}")
    if max_s is not None and (isinstance(max_s, bool) or not isinstance(max_s, int | float)
                              or not math.isfinite(max_s) or max_s <= 0):
        raise FileFormatError(f"{path} [env]: max_episode_s must be a number of seconds > 0, got {max_s!r}")
    return max_steps, max_s


def _confine_paths(path: Path, table: dict[str, Any], section: str, key: str) -> dict[str, Any]:
    """A file named in a scenario (a track CSV, a detector model) is read relative to the scenario's
    folder and must stay inside it (``weather_gym.core._io.resolve_inside``); names are kept as they are."""

    value = table.get(key)
    prefix, file = "", value
    if key == "track":  # a track spec names a file only sometimes, after its reverse: / mirror: prefixes
        prefix, file = track_file_part(value) or ("", None)
    if not isinstance(file, str):
        return table
    where = f"{path} [{section}] {key}"
    return {**table, key: prefix + str(resolve_inside(path.parent, file, what=where))}


def _confine_detector(path: Path, table: dict[str, Any]) -> dict[str, Any]:
    """``detector = "yolov8:model.onnx"`` (a detector spec, ``weather_gym.perception.detector_spec``): the
    model file after the kind is confined to the scenario's folder; a bare path is confined whole and
    a kind without a file (``"conenet"``, the shipped model) is kept."""
    value = table.get("detector")
    if not isinstance(value, str):
        return table
    head, sep, tail = value.partition(":")
    if sep and len(head) > 1 and head.replace("_", "").isalnum():  # KIND:FILE (the kind is checked when it is built)
        if not tail:
            return table
        where = f"{path} [perception] detector"
        return {**table, "detector": f"{head}:{resolve_inside(path.parent, tail, what=where)}"}
    if not sep and not value.lower().endswith(".onnx") and value.replace("_", "").isalnum():
        return table  # a kind without a file: the shipped model ("conenet")
    return _confine_paths(path, table, "perception", "detector")


def _check_weather(path: Path, weather: dict[str, Any]) -> None:
    """The scenario's weather must parse now, naming the file (not fail later, at ``gym.make``)."""

    if "spec" in weather and ("condition" in weather or "severity" in weather):
        raise FileFormatError(f"{path}: [weather] takes either spec or condition/severity, not both")
    try:
        if "spec" in weather:
            parse_weather(weather["spec"])
        elif "condition" in weather:
            sev = weather.get("severity", 0)
            if not isinstance(sev, int) or isinstance(sev, bool):
                raise InputError(f"severity must be an integer 0-4, got {sev!r}")
            parse_weather((weather["condition"], sev))
        elif "severity" in weather:
            raise InputError("severity needs a condition (e.g. condition = \"low_light\")")
    except InputError as exc:
        raise FileFormatError(f"{path}: [weather]: {exc}") from None


def _merge_section(cls: type, base: dict[str, Any], override: Any, name: str) -> Any:
    if override is None:
        return cls.from_dict(base) if cls is CameraModel else cls(**base)
    if is_dataclass(override):
        if not isinstance(override, cls):
            raise InputError(f"{name} must be a {cls.__name__} or a dict of its fields, got {type(override).__name__}")
        return override
    if isinstance(override, dict):
        check_known(override, {f.name for f in fields(cls)}, what=f"override {name}")
        merged = {**base, **override}
        return cls.from_dict(merged) if cls is CameraModel else cls(**merged)
    raise InputError(f"{name} must be a {cls.__name__} or a dict of its fields, got {override!r}")


def build_config(scenario: Scenario, overrides: dict[str, Any] | None = None) -> EnvConfig:
    """The ``EnvConfig`` of a scenario with keyword overrides (``gym.make`` kwargs) applied."""
    overrides = dict(overrides or {})
    check_known(overrides, (*ENV_KEYS, *SECTIONS), what=f"overrides for {scenario.env_id}")
    kwargs: dict[str, Any] = dict(scenario.env)
    for key in ENV_KEYS:
        if key in overrides:
            kwargs[key] = overrides[key]
    for name, cls in SECTIONS.items():
        kwargs[name] = _merge_section(cls, scenario.sections.get(name, {}), overrides.get(name), name)
    return EnvConfig(**kwargs)


def config_as_dict(config: EnvConfig) -> dict[str, Any]:
    """JSON-friendly dict of an ``EnvConfig``."""
    return dataclasses.asdict(config)
