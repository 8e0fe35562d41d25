"""The robustness evaluation: one cell = one agent driving one track in one weather preset with one seed.

``EvalConfig`` describes the grid (agents x effects x severities x seeds x tracks), ``make_cells``
expands it into ``EvalCell`` s (every field that changes the result is in the cell, so a results file
never mixes configurations silently; what the fields do not name, the model files and the resolved
scenario, is fingerprinted in ``stack``: see :func:`stack_id`), ``run_cell`` drives one episode and returns its metrics, and
``evaluate`` runs the grid on :func:`weather_gym.lab.evaluation.runner.run_cells` (parallel, resumable)
and returns the rows; the report (:func:`weather_gym.lab.evaluation.report.write_report`) is written by
its caller (``weather-gym evaluate``).

Severity -> weather goes through :func:`weather_gym.weather.presets.preset_spec` (the shipped
``presets.toml``; ``dim`` is an alias of the ``low_light`` condition). The resolved effect list is a
field of the cell (``weather``): when calibration rewrites the presets, old rows no longer match and
the cells run again; nothing here changes.

Pipeline of a cell: :func:`weather_gym.pipeline.make_env` (``env_id``, ``track``, ``laps``,
``max_episode_steps``, ``env_kwargs``; weather: the cell's preset; perception: a mode of
``weather_gym.pipeline.modes.PERCEPTION_MODES``) -> the agent from ``AGENTS`` -> one episode of
:func:`weather_gym.pipeline.run_episode` from ``reset(seed=seed)`` -> every metric of
:data:`weather_gym.lab.evaluation.metrics.METRICS`.

Example:
    >>> import json
    >>> from weather_gym.lab.evaluation.evaluate import EvalConfig, make_cells
    >>> cells = make_cells(EvalConfig(effects=("droplets", "dim"), severities=(0, 3), seeds=(0,)))
    >>> len(cells), cells[-1].effect, cells[-1].severity, json.loads(cells[-1].weather)[0]["name"]
    (4, 'dim', 3, 'dim')
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import numbers
import re
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from functools import partial
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np

from weather_gym.agents import agent_factory, agent_observes, make_agent
from weather_gym.agents.mapper import MapperConfig
from weather_gym.agents.sb3 import model_sidecar
from weather_gym.conditions import parse_state
from weather_gym.core._io import file_id
from weather_gym.core.errors import InputError
from weather_gym.core.paths import PPO_CONES_MODEL
from weather_gym.envs.cone_track import ConeTrackEnv
from weather_gym.envs.config import EnvConfig
from weather_gym.envs.registration import check_env_id
from weather_gym.envs.scenario import build_config, load_scenario
from weather_gym.lab.evaluation.metrics import (
    MAP_MATCH_RADIUS_M,
    METRICS,
    ConeListScoring,
    DetectorScoring,
    Episode,
    episode_metrics,
    map_precision_recall,
)
from weather_gym.lab.evaluation.runner import check_results_path, run_cells
from weather_gym.lidar_weather import LIDAR_EFFECTS, parse_lidar_weather
from weather_gym.pipeline import make_env
from weather_gym.pipeline.episode import run_episode
from weather_gym.pipeline.modes import (
    PERCEPTION_MODES,
    PerceptionMode,
    check_agent_observes,
    check_perception_kwargs,
    detector_mode,
    perception_mode,
)
from weather_gym.pipeline.presets_default import default_presets
from weather_gym.ros.episode_bag import BAG_IMAGES, ConeNoise, EpisodeBag
from weather_gym.tracks import load_track
from weather_gym.weather.presets import ALIASES, CONDITIONS, canonical_condition, preset_source, preset_spec

__all__ = [
    "CELL_KEY_FIELDS",
    "DEFAULT_ENV_ID",
    "DEFAULT_TRACK",
    "EvalCell",
    "EvalConfig",
    "MAP_MATCH_RADIUS_M",
    "METRICS",
    "PERCEPTIONS",
    "evaluate",
    "evaluate_stacks",
    "make_cells",
    "map_precision_recall",
    "run_cell",
    "stack_id",
]

DEFAULT_ENV_ID = "WeatherGym/ConeTrack-v0"
DEFAULT_TRACK = "small_track"
PERCEPTIONS = tuple(PERCEPTION_MODES)
"""Every perception mode (at import time; :data:`~weather_gym.pipeline.modes.PERCEPTION_MODES` is the registry)."""
DEFAULT_PERCEPTION = detector_mode().name
"""The evaluation's default perception: the first mode that runs the detector."""


def _json(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(", ", ": "))


@dataclass(frozen=True)
class EvalCell:
    """One cell of the grid; all fields are key fields of the results file.

    Mapping-valued settings are stored as canonical JSON text so the cell is hashable and a CSV
    column holds them as they are.
    """

    agent: str
    effect: str
    severity: int
    seed: int
    track: str
    env_id: str = DEFAULT_ENV_ID
    perception: str = DEFAULT_PERCEPTION
    laps: int = 1
    max_steps: int = 3000
    weather: str = "[]"  # the preset's effect list, JSON
    agent_kwargs: str = "{}"
    env_kwargs: str = "{}"
    perception_kwargs: str = "{}"
    stack: str = ""  # stack_id(): the resolved scenario and the model files the cell runs with
    k_source: str = ""  # where the preset's k came from (pool / resolved / file); not a key field: k is in weather


CELL_KEY_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(EvalCell) if f.name != "k_source")


@dataclass(frozen=True)
class EvalConfig:
    """The evaluation grid and the settings shared by its cells.

    Attributes:
        agents: names in ``weather_gym.agents.AGENTS``, or agents of your own as ``"module.path:Factory"``
            (importable by the workers too: installed, or on ``PYTHONPATH``).
        effects: weather conditions or their effect names (``droplets``, ``dim``/``low_light``); with
            perception ``lidar``, the LiDAR's effects (``fog``, ``rain``, ``snow``, ``wet``).
        severities: preset severities (0-4); the LiDAR's are 0-5 (its published grids).
        seeds: episode seeds (``reset(seed=...)``: weather realisation, odometry noise, ...).
        tracks: track names, ``random:SEED``, ``reverse:SPEC``, ``mirror:SPEC`` or cone CSV paths (anything
            ``gymnasium.make(track=...)`` takes).
        env_id: a Gymnasium id registered by weather-gym (a scenario).
        perception: a mode of ``weather_gym.pipeline.modes.PERCEPTION_MODES`` (default: the
            ONNX detector); a mode that takes no weather runs at severity 0 only.
        laps: laps per episode; max_steps: the episode's time limit in steps (``TimeLimit``).
        agent_kwargs, env_kwargs, perception_kwargs: JSON-able keyword arguments of the agent factory,
            of ``gymnasium.make`` (e.g. ``{"camera": {"width": 336, "height": 188}}``) and of the
            perception wrapper (``DetectorWrapper``: ``score_threshold``, ``max_cones``...;
            ``GroundTruthConeWrapper``: ``OracleNoise`` fields such as ``miss_prob``).
        presets: a presets TOML file (default: resolved for each track, unless ``$WEATHER_GYM_PRESETS`` is ``pool`` or a file), or
            one per track (``{track: file}``, e.g. each resolved for its track: ``weather-gym evaluate
            --presets resolved``). ``results.csv`` has the k's in ``weather`` and their source in ``k_source``.
        conditions: physical weather states (``"rain:8mm/h"``, ``"fog:60m+dusk:20lux"``, ``"clear"``;
            :mod:`weather_gym.conditions`): given, they are the grid's weathers instead of ``effects`` x
            ``severities`` (each a cell with ``effect`` = the state's spec, ``severity`` 0), reaching the
            camera, the LiDAR and the tyres of any perception mode.
    """

    agents: tuple[str, ...] = ("mapper_pure_pursuit",)
    effects: tuple[str, ...] = ("droplets", "dim")
    severities: tuple[int, ...] = (0, 1, 2, 3, 4)
    seeds: tuple[int, ...] = (0, 1, 2)
    tracks: tuple[str, ...] = (DEFAULT_TRACK,)
    env_id: str = DEFAULT_ENV_ID
    perception: str = DEFAULT_PERCEPTION
    laps: int = 1
    max_steps: int = 3000
    agent_kwargs: Mapping[str, Any] = field(default_factory=dict)
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    perception_kwargs: Mapping[str, Any] = field(default_factory=dict)
    presets: str | Mapping[str, str] | None = None
    conditions: tuple[str, ...] = ()


def _check_int(name: str, value: Any, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or int(value) < lo:
        raise InputError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def _check_names(what: str, values: Sequence[Any]) -> tuple[Any, ...]:
    if isinstance(values, str):
        raise InputError(f"{what} must be a list of names, got the string {values!r}")
    values = tuple(values)
    if not values:
        raise InputError(f"the list of {what} is empty; give at least one")
    dup = sorted({v for v in values if values.count(v) > 1})
    if dup:
        raise InputError(f"{what} repeated: {', '.join(map(str, dup))}")
    return values


def _jsonable(what: str, value: Mapping[str, Any]) -> str:
    if not isinstance(value, Mapping):
        raise InputError(f"{what} must be a mapping of keyword arguments, got {value!r}")
    try:
        return _json(dict(value))
    except TypeError as exc:
        raise InputError(f"{what} must be JSON-serialisable (numbers, strings, lists, dicts): {exc}") from None


def _resolved_env(config: EvalConfig) -> EnvConfig | None:
    """The scenario of ``config.env_id`` with ``env_kwargs`` applied (None for an id without one)."""
    scenario = (gym.registry[config.env_id].kwargs or {}).get("scenario")
    if scenario is None:
        return None
    try:
        return build_config(load_scenario(scenario), dict(config.env_kwargs))
    except InputError as exc:
        raise type(exc)(f"env_kwargs: {exc}") from None


def stack_id(config: EvalConfig, agent: str, *, env_config: EnvConfig | None = None) -> str:
    """12 hex digits of what ``agent``'s cells of ``config`` depend on beyond their other key fields:
    the scenario as resolved (its TOML with the code's defaults and ``env_kwargs``: world, camera
    model, car...), the detector's model file and options (perception ``detector``), the surrogate's
    model file (``surrogate``) and the agent's policy file (``ppo_cones``, ``sb3``'s ``path``) with its
    JSON sidecar.

    So a results file resumed after the detector, a default or a scenario changed runs its cells
    again instead of mixing old rows in. Changes of the code itself are not seen: after one, use a
    new output folder (or delete ``results.sqlite`` and ``results.csv``). ``env_config``: the resolved scenario, when the
    caller has it already.
    """

    parts: dict[str, str] = {}
    resolved = env_config if env_config is not None else _resolved_env(config)
    parts["env"] = repr(resolved) if resolved is not None else config.env_id
    fingerprint = perception_mode(config.perception).fingerprint
    if fingerprint is not None:
        parts.update(fingerprint(dict(config.perception_kwargs)))
    policy = dict(config.agent_kwargs).get("path") if agent == "sb3" else PPO_CONES_MODEL if agent == "ppo_cones" else None
    if isinstance(policy, (str, Path)) and Path(policy).is_file():
        parts["policy"] = file_id(policy)
        sidecar = model_sidecar(policy)  # the agent reads its settings (the cone memory) from there
        if sidecar is not None:
            parts["policy_sidecar"] = file_id(sidecar)
    return hashlib.sha256(_json(parts).encode()).hexdigest()[:12]


def validate_config(config: EvalConfig) -> None:
    """Check every name and number of ``config`` (``ValueError`` naming the bad value and the valid ones)."""
    make_cells(config)


def make_cells(config: EvalConfig) -> list[EvalCell]:
    """Expand ``config`` into cells, validating it first (order: agent, track, effect, severity, seed).

    Raises ``ValueError`` for an unknown agent, effect, env id or perception (listing the valid ones),
    a severity outside the preset scale, an empty list, a repeated entry, or non-JSON kwargs.
    """


    agents = _check_names("agents", config.agents)
    for a in agents:
        agent_factory(a)  # ValueError lists the valid names; 'module:Factory' is imported
    tracks = _check_names("tracks", config.tracks)

    for t in tracks:
        if not isinstance(t, str) or not t:
            raise InputError(f"a track must be a non-empty name or path, got {t!r}")
        load_track(t)  # unknown names list the valid ones; a bad CSV names its line
    mode = perception_mode(config.perception)
    if config.conditions:
        return _condition_cells(config, agents, tracks, mode)
    effects = _check_names("effects", config.effects)
    if not mode.takes_lidar_weather:
        for e in effects:
            canonical_condition(e)
        if len({canonical_condition(e) for e in effects}) != len(effects):
            raise InputError(f"effects {', '.join(effects)} name the same condition twice (dim is low_light)")
    severities = _check_names("severities", config.severities)
    seeds = tuple(_check_int("a seed", s, 0) for s in _check_names("seeds", config.seeds))
    check_env_id(config.env_id)
    laps = _check_int("laps", config.laps, 1)
    max_steps = _check_int("max_steps", config.max_steps, 1)
    agent_kwargs = _jsonable("agent_kwargs", config.agent_kwargs)
    env_kwargs = _jsonable("env_kwargs", config.env_kwargs)
    perception_kwargs = _jsonable("perception_kwargs", config.perception_kwargs)
    clash = sorted(set(config.env_kwargs) & {"track", "laps", "max_episode_steps", "weather", "severity", "detector"})
    if clash:
        raise InputError(f"env_kwargs may not set {', '.join(clash)}: the evaluation sets them per cell")
    clash = sorted(set(config.env_kwargs) & {"perception", "perception_kwargs"})
    if clash:
        raise InputError(f"env_kwargs may not set {', '.join(clash)}: use EvalConfig.perception / perception_kwargs")
    env_config = _resolved_env(config)  # camera sizes and other overrides are checked now, not in every cell
    _check_perception_kwargs(config.perception, dict(config.perception_kwargs))
    for a in agents:
        check_agent_observes(a, agent_observes(a), mode)
    if config.agent_kwargs:  # a bad agent argument fails now, not in every cell
        for a in agents:
            _check_agent_kwargs(a, load_track(tracks[0]), env_config.camera, dict(config.agent_kwargs))  # type: ignore[union-attr]  # None for an id without a scenario: AttributeError (a known gap)

    weather, source = _cell_weather(config, mode, tracks, effects, severities, env_config)
    stacks = {a: stack_id(config, a, env_config=env_config) for a in agents}
    cells = [
        EvalCell(agent=a, effect=e, severity=int(s), seed=seed, track=t, env_id=config.env_id,
                 perception=config.perception, laps=laps, max_steps=max_steps, weather=weather[t, e, s],
                 agent_kwargs=agent_kwargs, env_kwargs=env_kwargs, perception_kwargs=perception_kwargs,
                 stack=stacks[a], k_source=source[t] if int(s) > 0 else "given")
        for a in agents for t in tracks for e in effects for s in severities for seed in seeds
    ]
    return cells


def _condition_cells(config: EvalConfig, agents: Sequence[str], tracks: Sequence[str], mode: Any) -> list[EvalCell]:
    """The cells of a grid over physical weather states (``config.conditions``)."""
    specs = [parse_state(c).spec() for c in _check_names("conditions", config.conditions)]
    dup = sorted({s for s in specs if specs.count(s) > 1})
    if dup:
        raise InputError(f"conditions name the same state twice: {', '.join(dup)}")
    if mode.name == "surrogate":
        raise InputError("conditions do not reach perception 'surrogate'; take detector, lidar or fused")
    if "lidar_weather" in config.perception_kwargs:
        raise InputError("perception_kwargs may not set lidar_weather: the conditions set it per cell")
    seeds = tuple(_check_int("a seed", s, 0) for s in _check_names("seeds", config.seeds))
    check_env_id(config.env_id)
    laps, max_steps = _check_int("laps", config.laps, 1), _check_int("max_steps", config.max_steps, 1)
    agent_kwargs = _jsonable("agent_kwargs", config.agent_kwargs)
    env_kwargs = _jsonable("env_kwargs", config.env_kwargs)
    perception_kwargs = _jsonable("perception_kwargs", config.perception_kwargs)
    env_config = _resolved_env(config)
    _check_perception_kwargs(config.perception, dict(config.perception_kwargs))
    for a in agents:
        check_agent_observes(a, agent_observes(a), mode)
    stacks = {a: stack_id(config, a, env_config=env_config) for a in agents}
    return [EvalCell(agent=a, effect=spec, severity=0, seed=seed, track=t, env_id=config.env_id,
                     perception=config.perception, laps=laps, max_steps=max_steps,
                     weather=_json({"conditions": spec}), agent_kwargs=agent_kwargs, env_kwargs=env_kwargs,
                     perception_kwargs=perception_kwargs, stack=stacks[a], k_source="given")
            for a in agents for t in tracks for spec in specs for seed in seeds]


def _cell_weather(config: EvalConfig, mode: Any, tracks: Sequence[str], effects: Sequence[str],
                  severities: Sequence[int], env_config: Any = None
                  ) -> tuple[dict[tuple[str, str, int], str], dict[str, str]]:
    """Every cell's weather (JSON) by (track, effect, severity), and where each track's k come from:
    the LiDAR's published grids (given), or the presets (per track where ``config.presets`` maps them;
    none given: resolved for each track, the default meaning, where the mode's frames see the weather)."""
    resolved: dict[str, str | None] = {}

    def presets_of(t: str) -> str | None:
        if isinstance(config.presets, Mapping):
            if t not in config.presets:
                raise InputError(f"presets per track: no presets file for track {t!r} (given for "
                                 f"{', '.join(map(repr, config.presets))})")
            return config.presets[t]
        if config.presets is None and env_config is not None and mode.renders_frames and mode.takes_weather:
            if t not in resolved:
                cells = [(e, s) for e in effects for s in severities if e in CONDITIONS or e in ALIASES]
                detector = config.perception_kwargs.get("detector") if mode.runs_detector else None
                resolved[t] = default_presets(cells, dataclasses.replace(env_config, track=t), detector)
            return resolved[t]
        return config.presets

    if mode.takes_lidar_weather:  # the LiDAR's own weather: effects fog, rain, snow, wet at severities 0-5
        if "lidar_weather" in config.perception_kwargs:
            raise InputError("perception_kwargs may not set lidar_weather: the evaluation sets it per cell "
                             "from effects and severities")
        weather = {(t, e, s): _json(_lidar_spec(e, s)) for t in tracks for e in effects for s in severities}
        return weather, {t: "given" for t in tracks}  # the LiDAR's severities are its published grids
    weather = {(t, e, s): _json(preset_spec(e, s, presets_of(t))) for t in tracks for e in effects
               for s in severities}
    _check_weather_for_mode(mode, {(e, s): w for (_, e, s), w in weather.items()}, config.perception_kwargs)
    return weather, {t: preset_source(presets_of(t)) for t in tracks}


def _lidar_spec(effect: str, severity: Any) -> str:
    """The LiDAR weather spec of ``effect`` at ``severity`` (0-5), checked (``LIDAR_EFFECTS``)."""
    spec = "clear" if severity == 0 else f"{effect}@{severity}"
    LIDAR_EFFECTS.get(effect)  # an unknown effect lists the valid ones
    parse_lidar_weather(spec)  # a severity outside 0-5 fails here
    return spec


def _check_weather_for_mode(mode: PerceptionMode, weather: Mapping[tuple[str, Any], str],
                            perception_kwargs: Mapping[str, Any]) -> None:
    """Refuse, before any cell runs, a weather (``{(effect, severity): spec JSON}``) that perception ``mode``
    cannot produce, and any weather at all for a mode that renders no camera frame."""
    if mode.check_weather is not None:
        for (e, s), w in weather.items():
            try:
                mode.check_weather(dict(perception_kwargs), w)
            except InputError as exc:
                raise type(exc)(f"perception {mode.name}, {e}@{s}: {exc}") from None
    if not mode.takes_weather:
        wet = sorted(f"{e}@{s}" for (e, s), w in weather.items() if json.loads(w))
        if wet:
            raise InputError(f"perception {mode.name} renders no camera frame, so weather cannot act on it; "
                             f"{', '.join(wet)} would be clear weather: evaluate {mode.name} at severity 0 only")


def _check_perception_kwargs(perception: str, kwargs: dict[str, Any]) -> None:
    """Refuse keys the perception wrapper does not take, and bad oracle noise values, before any cell runs."""
    check_perception_kwargs(perception, kwargs, what="--perception-kwargs")


def _check_agent_kwargs(name: str, track: Any, camera: Any, kwargs: dict[str, Any]) -> None:
    """Build agent ``name`` once with ``kwargs``: an unknown or bad argument fails before any cell runs."""
    try:
        make_agent(name, track, camera, **kwargs)
    except InputError as exc:
        raise InputError(f"--agent-arg for agent {name!r}: {exc}") from None
    except TypeError as exc:
        if "keyword argument" not in str(exc):
            raise  # not the arguments' fault: a bug keeps its traceback
        raise InputError(f"--agent-arg for agent {name!r}: {exc}") from None


# ------------------------------------------------------------------------------------------ the cell
BAGS = "bags"
"""The folder under the results folder that ``evaluate(..., bags=True)`` writes one MCAP bag per cell into."""


def bag_name(cell: EvalCell) -> str:
    """The folder name of a cell's bag: agent, effect and severity, track, seed and a hash of every field."""
    key = hashlib.sha1(json.dumps(asdict(cell), sort_keys=True).encode()).hexdigest()[:8]
    track = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(cell.track).stem if cell.track.endswith(".csv") else cell.track)
    return f"{cell.agent}-{cell.effect}{cell.severity}-{track}-seed{cell.seed}-{key}"


def run_cell(cell: EvalCell | Mapping[str, Any], *, bag_dir: str | None = None,
             bag_images: str = "jpeg") -> dict[str, Any]:
    """Drive one episode of ``cell`` and return the metrics in :data:`METRICS` (NaN/None where not defined).

    ``bag_dir``: also write the episode as an MCAP rosbag2 into ``bag_dir/``:func:`bag_name`
    (:class:`~weather_gym.ros.episode_bag.EpisodeBag`; a bag of the same cell from an earlier try is replaced).
    """

    if isinstance(cell, Mapping):
        cell = EvalCell(**cell)
    mode = perception_mode(cell.perception)
    weather, perception_kwargs = json.loads(cell.weather), json.loads(cell.perception_kwargs)
    conditions = weather.get("conditions") if isinstance(weather, dict) else None
    if conditions is not None:  # one physical state for the camera, the LiDAR and the tyres
        weather = None
    elif mode.takes_lidar_weather:  # the cell's weather is the LiDAR's
        weather, perception_kwargs = None, {**perception_kwargs, "lidar_weather": weather}
    if bag_dir is not None and mode.can_record_video:
        perception_kwargs = {**perception_kwargs, **mode.record_kwargs}  # keep the camera frame for the bag
    env = make_env(cell.env_id, track=cell.track, laps=cell.laps, max_episode_steps=cell.max_steps,
                   weather=weather, perception=mode.name, perception_kwargs=perception_kwargs,
                   conditions=conditions, **json.loads(cell.env_kwargs))
    bag: EpisodeBag | None = None
    try:
        base = cast(ConeTrackEnv, env.unwrapped)
        track, camera = base.track, base.config.camera
        agent = make_agent(cell.agent, track, camera, **json.loads(cell.agent_kwargs))
        # every frame the agent acts on (the reset frame included, the final one not)
        scoring = DetectorScoring(mode)
        cone_list = ConeListScoring(track.cones_xy, half_fov=np.radians(camera.hfov_deg) / 2, mount_x=camera.mount_x)

        def on_step(step: int, obs: Any, info: dict, done: bool) -> None:
            nonlocal bag
            scoring(step, obs, info, done)
            cone_list(step, obs, info, done)
            if bag_dir is None:
                return
            if step == 0:
                m = MapperConfig()  # the cones' covariance: the mapper's range/bearing noise model
                bag = EpisodeBag.for_env(Path(bag_dir) / bag_name(cell), base, weathered="weather" in info,
                                         images=bag_images, overwrite=True,
                                         noise=ConeNoise(m.range_std, m.range_std_rel, m.bearing_std))
            assert bag is not None  # made on the first step
            bag.add_step(base, obs, info)

        try:
            res = run_episode(env, agent, seed=cell.seed, on_step=on_step, agent_name=cell.agent)
        except BaseException as exc:
            if bag is not None:
                bag.__exit__(type(exc), exc, None)  # no half-written bag
            raise
        if bag is not None:
            bag.__exit__(None, None, None)
        metrics = episode_metrics(Episode(res, agent, track, mode, scoring.scores(), cone_list=cone_list.scores()))
        return {"k_source": cell.k_source, **metrics} if cell.k_source else metrics
    finally:
        env.close()


# ----------------------------------------------------------------------------------------- the grid
def evaluate(config: EvalConfig, out_dir: str | Path, *, workers: int | None = None, backend: str = "process",
             ray_address: str | None = None, progress: bool = True, retry_failed: bool = True,
             bags: bool = False, bag_images: str = "jpeg") -> list[dict[str, Any]]:
    """Run the grid of ``config`` into ``out_dir/results.csv`` (resuming) and return this grid's rows
    (see :data:`METRICS`). The report is its caller's to write
    (:func:`weather_gym.lab.evaluation.report.write_report`; ``weather-gym evaluate`` does).
    ``bags``: every cell this run drives also writes its episode as an MCAP bag into ``out_dir/bags/``
    (cells resumed from ``results.csv`` are not driven again, so they get none).
    """

    cells = make_cells(config)
    results = check_results_path(Path(out_dir) / "results.csv")
    if bag_images not in BAG_IMAGES:
        raise InputError(f"--bag-images must be one of {', '.join(BAG_IMAGES)}, got {bag_images!r}")
    cell_fn = partial(run_cell, bag_dir=str(Path(out_dir) / BAGS), bag_images=bag_images) if bags else run_cell
    return run_cells(cells, cell_fn, results, key_fields=CELL_KEY_FIELDS, workers=workers, backend=backend,
                     ray_address=ray_address, progress=progress, retry_failed=retry_failed, desc="evaluate")


def evaluate_stacks(configs: Sequence[EvalConfig], out_dir: str | Path, *, workers: int | None = None,
                    backend: str = "process", ray_address: str | None = None, progress: bool = True,
                    retry_failed: bool = True) -> list[dict[str, Any]]:
    """Run the grids of several ``configs`` (one per perception stack: the same tracks, weathers and seeds)
    into one ``out_dir/results.csv``, all cells in one pool, and return their rows."""
    cells = [c for config in configs for c in make_cells(config)]
    results = check_results_path(Path(out_dir) / "results.csv")
    return run_cells(cells, run_cell, results, key_fields=CELL_KEY_FIELDS, workers=workers, backend=backend,
                     ray_address=ray_address, progress=progress, retry_failed=retry_failed, desc="evaluate")


def config_summary(config: EvalConfig) -> dict[str, Any]:
    """JSON-friendly dict of a config (for reports)."""
    d = asdict(config)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}
