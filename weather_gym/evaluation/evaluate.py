"""The robustness evaluation: one cell = one agent driving one track in one weather preset with one seed.

``EvalConfig`` describes the grid (agents x effects x severities x seeds x tracks), ``make_cells``
expands it into ``EvalCell`` s (every field that changes the result is in the cell, so a results file
never mixes configurations silently), ``run_cell`` drives one episode and returns its metrics, and
``evaluate`` runs the grid on :func:`weather_gym.evaluation.runner.run_cells` (parallel, resumable).

Severity -> weather goes through :func:`weather_gym.weather.presets.preset_spec` (the shipped
``presets.toml``; ``dim`` is an alias of the ``low_light`` condition). The resolved effect list is a
field of the cell (``weather``): when calibration rewrites the presets, old rows no longer match and
the cells run again; nothing here changes.

Pipeline of a cell: ``gymnasium.make(env_id, track=..., laps=..., **env_kwargs)`` ->
``WeatherWrapper(weather)`` -> perception (``detector``: ``DetectorWrapper``; ``oracle``: the
ground-truth cone list; ``camera``: none, the agent gets the weathered image) -> the agent from
``AGENTS`` -> one episode from ``reset(seed=seed)``.

Example:
    >>> import json
    >>> from weather_gym.evaluation.evaluate import EvalConfig, make_cells
    >>> cells = make_cells(EvalConfig(effects=("droplets", "dim"), severities=(0, 3), seeds=(0,)))
    >>> len(cells), cells[-1].effect, cells[-1].severity, json.loads(cells[-1].weather)[0]["name"]
    (4, 'dim', 3, 'dim')
"""

from __future__ import annotations

import json
import math
import numbers
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.errors import InputError

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
    "make_cells",
    "make_eval_env",
    "map_precision_recall",
    "run_cell",
]

DEFAULT_ENV_ID = "WeatherGym/ConeTrack-v0"
DEFAULT_TRACK = "small_track"
PERCEPTIONS = ("detector", "oracle", "camera")
MAP_MATCH_RADIUS_M = 0.5
"""A mapped cone counts as correct within this distance of a true cone (and vice versa for recall)."""

METRICS: dict[str, str] = {
    "laps_completed": "laps finished in the episode",
    "completed": "1 if all requested laps were finished, else 0",
    "lap_time_s": "mean time of the finished laps (s; empty if none)",
    "progress": "distance driven along the centre line / (track length x laps), 0..1",
    "cones_hit": "distinct cones touched",
    "off_track_events": "times the car left the track",
    "cte_mean_m": "mean cross-track error over the steps (m)",
    "cte_max_m": "max cross-track error (m)",
    "end_reason": "laps | off_track | time_limit | ended (the env terminated for another reason)",
    "steps": "env steps driven",
    "sim_time_s": "simulated time (s)",
    "map_cones": "confirmed cones in the agent's map at the end (empty if the agent has no map)",
    "map_precision": f"share of mapped cones within {MAP_MATCH_RADIUS_M} m of a true cone",
    "map_recall": f"share of the track's cones within {MAP_MATCH_RADIUS_M} m of a mapped cone",
    "det_map50": "detector mAP@0.5 (pycocotools) pooled over the frames seen (empty unless perception=detector)",
    "det_recall": "detector recall at its operating threshold over the frames seen",
    "det_frames": "frames scored for det_map50",
    "weather_latency_ms": "mean time the weather added per step (ms)",
    "detector_latency_ms": "mean time the detector added per step (ms; 0 without a detector)",
    "added_latency_ms": "weather_latency_ms + detector_latency_ms",
}
"""Every metric ``run_cell`` returns, with its meaning (the columns after the key fields)."""


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
    perception: str = "detector"
    laps: int = 1
    max_steps: int = 3000
    weather: str = "[]"  # the preset's effect list, JSON
    agent_kwargs: str = "{}"
    env_kwargs: str = "{}"
    perception_kwargs: str = "{}"


CELL_KEY_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(EvalCell))


@dataclass(frozen=True)
class EvalConfig:
    """The evaluation grid and the settings shared by its cells.

    Attributes:
        agents: names in ``weather_gym.agents.AGENTS``.
        effects: weather conditions or their effect names (``droplets``, ``dim``/``low_light``).
        severities: preset severities (0-4).
        seeds: episode seeds (``reset(seed=...)``: weather realisation, odometry noise, ...).
        tracks: track names, ``random:SEED`` or cone CSV paths (anything ``gymnasium.make(track=...)`` takes).
        env_id: a Gymnasium id registered by weather-gym (a scenario).
        perception: ``detector`` (the ONNX detector), ``oracle`` (ground-truth cone list) or
            ``camera`` (no perception; the agent gets the weathered image).
        laps: laps per episode; max_steps: step limit per episode (``gymnasium.make(max_episode_steps=)``;
            the scenario's own limit still applies).
        agent_kwargs, env_kwargs, perception_kwargs: JSON-able keyword arguments of the agent factory,
            of ``gymnasium.make`` (e.g. ``{"camera": {"width": 336, "height": 188}}``) and of the
            perception wrapper (``DetectorWrapper``: ``score_threshold``, ``max_cones``...;
            ``GroundTruthConeWrapper``: ``OracleNoise`` fields such as ``miss_prob``).
        presets: a presets TOML file (default: the shipped ``presets.toml``).
    """

    agents: tuple[str, ...] = ("mapper_pure_pursuit",)
    effects: tuple[str, ...] = ("droplets", "dim")
    severities: tuple[int, ...] = (0, 1, 2, 3, 4)
    seeds: tuple[int, ...] = (0, 1, 2)
    tracks: tuple[str, ...] = (DEFAULT_TRACK,)
    env_id: str = DEFAULT_ENV_ID
    perception: str = "detector"
    laps: int = 1
    max_steps: int = 3000
    agent_kwargs: Mapping[str, Any] = field(default_factory=dict)
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    perception_kwargs: Mapping[str, Any] = field(default_factory=dict)
    presets: str | None = None


def _check_int(name: str, value: Any, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or int(value) < lo:
        raise InputError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def _check_names(what: str, values: Sequence[Any]) -> tuple[str, ...]:
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


def validate_config(config: EvalConfig) -> None:
    """Check every name and number of ``config`` (``ValueError`` naming the bad value and the valid ones)."""
    make_cells(config)


def make_cells(config: EvalConfig) -> list[EvalCell]:
    """Expand ``config`` into cells, validating it first (order: agent, track, effect, severity, seed).

    Raises ``ValueError`` for an unknown agent, effect, env id or perception (listing the valid ones),
    a severity outside the preset scale, an empty list, a repeated entry, or non-JSON kwargs.
    """
    import gymnasium as gym

    import weather_gym  # noqa: F401 - registers the env ids
    from weather_gym.agents import AGENTS
    from weather_gym.weather.presets import canonical_condition, preset_spec

    agents = _check_names("agents", config.agents)
    for a in agents:
        AGENTS.get(a)  # ValueError lists the valid names
    tracks = _check_names("tracks", config.tracks)
    from weather_gym.tracks import load_track

    for t in tracks:
        if not isinstance(t, str) or not t:
            raise InputError(f"a track must be a non-empty name or path, got {t!r}")
        load_track(t)  # unknown names list the valid ones; a bad CSV names its line
    effects = _check_names("effects", config.effects)
    for e in effects:
        canonical_condition(e)
    if len({canonical_condition(e) for e in effects}) != len(effects):
        raise InputError(f"effects {', '.join(effects)} name the same condition twice (dim is low_light)")
    severities = _check_names("severities", config.severities)
    seeds = tuple(_check_int("a seed", s, 0) for s in _check_names("seeds", config.seeds))
    if config.perception not in PERCEPTIONS:
        raise InputError(f"unknown perception {config.perception!r}; valid: {', '.join(PERCEPTIONS)}")
    if config.env_id not in gym.registry:
        ours = sorted(k for k in gym.registry if k.startswith("WeatherGym/"))
        raise InputError(f"unknown env id {config.env_id!r}; weather-gym ids: {', '.join(ours)}")
    laps = _check_int("laps", config.laps, 1)
    max_steps = _check_int("max_steps", config.max_steps, 1)
    agent_kwargs = _jsonable("agent_kwargs", config.agent_kwargs)
    env_kwargs = _jsonable("env_kwargs", config.env_kwargs)
    perception_kwargs = _jsonable("perception_kwargs", config.perception_kwargs)
    clash = sorted(set(config.env_kwargs) & {"track", "laps", "max_episode_steps", "weather", "severity", "detector"})
    if clash:
        raise InputError(f"env_kwargs may not set {', '.join(clash)}: the evaluation sets them per cell")
    scenario = (gym.registry[config.env_id].kwargs or {}).get("scenario")
    if scenario is not None:  # camera sizes and other overrides are checked now, not in every cell
        from weather_gym.envs.scenario import build_config, load_scenario

        try:
            build_config(load_scenario(scenario), dict(config.env_kwargs))
        except InputError as exc:
            raise type(exc)(f"env_kwargs: {exc}") from None
    weather = {(e, s): _json(preset_spec(e, s, config.presets)) for e in effects for s in severities}
    cells = [
        EvalCell(agent=a, effect=e, severity=int(s), seed=seed, track=t, env_id=config.env_id,
                 perception=config.perception, laps=laps, max_steps=max_steps, weather=weather[e, s],
                 agent_kwargs=agent_kwargs, env_kwargs=env_kwargs, perception_kwargs=perception_kwargs)
        for a in agents for t in tracks for e in effects for s in severities for seed in seeds
    ]
    return cells


# ------------------------------------------------------------------------------------------ the cell
def map_precision_recall(mapped_xy: np.ndarray, true_xy: np.ndarray,
                         radius: float = MAP_MATCH_RADIUS_M) -> tuple[float, float]:
    """Share of mapped cones within ``radius`` of a true cone, and of true cones within ``radius`` of
    a mapped one (class-agnostic; NaN precision for an empty map).

    Example:
        >>> import numpy as np
        >>> map_precision_recall(np.array([[0, 0.3], [5, 5]]), np.array([[0, 0], [1, 0], [2, 0], [3, 0.]]))
        (0.5, 0.25)
    """
    from scipy.spatial import cKDTree

    mapped_xy = np.asarray(mapped_xy, dtype=np.float64).reshape(-1, 2)
    true_xy = np.asarray(true_xy, dtype=np.float64).reshape(-1, 2)
    if len(true_xy) == 0:
        raise InputError("the track has no cones to compare the map with")
    if len(mapped_xy) == 0:
        return math.nan, 0.0
    d_map, _ = cKDTree(true_xy).query(mapped_xy)
    d_true, _ = cKDTree(mapped_xy).query(true_xy)
    return float(np.mean(d_map <= radius)), float(np.mean(d_true <= radius))


def _agent_map_xy(agent: Any) -> np.ndarray | None:
    """Confirmed map cones (odometry frame, which starts at the true start pose) of a mapping agent."""
    mapper = getattr(agent, "mapper", None)
    if mapper is None or not hasattr(mapper, "map"):
        return None
    return np.asarray(mapper.map(confirmed_only=True).xy, dtype=np.float64).reshape(-1, 2)


def _wrap_perception(env: Any, perception: str, perception_kwargs: dict[str, Any]) -> Any:
    """Add the perception of a cell: ``DetectorWrapper(**kw)``, ``GroundTruthConeWrapper(**kw)`` or none."""
    if perception == "detector":
        from weather_gym.wrappers import DetectorWrapper

        return DetectorWrapper(env, **perception_kwargs)
    if perception == "oracle":
        from weather_gym.wrappers import GroundTruthConeWrapper

        return GroundTruthConeWrapper(env, **perception_kwargs)
    if perception_kwargs:
        raise InputError(f"perception_kwargs {sorted(perception_kwargs)} given, but perception 'camera' takes none")
    return env


def make_eval_env(env_id: str = DEFAULT_ENV_ID, *, track: str | None = None, laps: int | None = None,
                  max_steps: int | None = None, weather: Any = None, perception: str = "detector",
                  env_kwargs: Mapping[str, Any] | None = None, perception_kwargs: Mapping[str, Any] | None = None):
    """The pipeline a cell drives: ``gymnasium.make`` -> ``WeatherWrapper(weather)`` -> perception.

    Training scripts build their envs with it too, so a policy is evaluated on the observation it
    was trained on. ``weather`` is any spec ``parse_weather`` takes (a preset ``("dim", 2)``, an
    effect list...); it can be changed per episode with ``reset(options={"weather": ...})``.

    Example:
        >>> env = make_eval_env(track="small_track", weather=("dim", 2), perception="oracle")  # doctest: +SKIP
        >>> sorted(env.observation_space.spaces)                                            # doctest: +SKIP
        ['cones', 'mask', 'state']
    """
    import gymnasium as gym

    import weather_gym  # noqa: F401 - registers the env ids
    from weather_gym.wrappers import WeatherWrapper

    if perception not in PERCEPTIONS:
        raise InputError(f"unknown perception {perception!r}; valid: {', '.join(PERCEPTIONS)}")
    kwargs = dict(env_kwargs or {})
    if track is not None:
        kwargs["track"] = track
    if laps is not None:
        kwargs["laps"] = laps
    if max_steps is not None:
        kwargs["max_episode_steps"] = max_steps
    env = gym.make(env_id, **kwargs)
    try:
        env = WeatherWrapper(env, weather=weather)
        return _wrap_perception(env, perception, dict(perception_kwargs or {}))
    except BaseException:
        env.close()
        raise


def _end_reason(info: dict, terminated: bool, truncated: bool, laps: int) -> str:
    if int(info.get("lap", 0)) >= laps or info.get("finished"):
        return "laps"
    if terminated and info.get("off_track"):
        return "off_track"
    if truncated:
        return "time_limit"
    return "ended"


def run_cell(cell: EvalCell | Mapping[str, Any]) -> dict[str, Any]:
    """Drive one episode of ``cell`` and return the metrics in :data:`METRICS` (NaN/None where not defined)."""
    from weather_gym.agents import check_action, make_agent

    if isinstance(cell, Mapping):
        cell = EvalCell(**cell)
    env = make_eval_env(cell.env_id, track=cell.track, laps=cell.laps, max_steps=cell.max_steps,
                        weather=json.loads(cell.weather), perception=cell.perception,
                        env_kwargs=json.loads(cell.env_kwargs), perception_kwargs=json.loads(cell.perception_kwargs))
    try:
        base = env.unwrapped
        track, camera = base.track, base.config.camera
        agent = make_agent(cell.agent, track, camera, **json.loads(cell.agent_kwargs))
        score_detector = cell.perception == "detector"
        obs, info = env.reset(seed=cell.seed)
        agent.reset(seed=cell.seed, info=info)
        cte: list[float] = []
        w_lat: list[float] = []
        d_lat: list[float] = []
        gts: list[dict] = []
        dets: list[Any] = []
        terminated = truncated = False
        steps = 0

        def seen(info: dict) -> None:  # every frame the agent acts on, the reset frame included
            if score_detector and info.get("gt") is not None and info.get("detections") is not None:
                gts.append(info["gt"])
                dets.append(info["detections"])

        seen(info)
        while not (terminated or truncated):
            action = check_action(agent.act(obs, info), who=f"agent {cell.agent!r}")
            obs, _reward, terminated, truncated, info = env.step(action)
            steps += 1
            cte.append(float(info["cross_track_error"]))
            w_lat.append(float(info.get("weather_latency_ms", 0.0)))
            d_lat.append(float(info.get("detector_latency_ms", 0.0)))
            if not (terminated or truncated):
                seen(info)
        lap_times = [float(t) for t in info.get("lap_times", [])]
        laps_done = int(info.get("lap", len(lap_times)))
        progress = float(info.get("progress", math.nan)) / (track.length * cell.laps)
        out: dict[str, Any] = {
            "laps_completed": laps_done,
            "completed": int(laps_done >= cell.laps or bool(info.get("finished"))),
            "lap_time_s": float(np.mean(lap_times)) if lap_times else None,
            "progress": float(np.clip(progress, 0.0, 1.0)) if math.isfinite(progress) else math.nan,
            "cones_hit": int(info["cones_hit"]),
            "off_track_events": int(info.get("off_track_events", int(bool(info.get("off_track"))))),
            "cte_mean_m": float(np.mean(cte)) if cte else math.nan,
            "cte_max_m": float(np.max(cte)) if cte else math.nan,
            "end_reason": _end_reason(info, terminated, truncated, cell.laps),
            "steps": steps,
            "sim_time_s": float(info.get("time", math.nan)),
        }
        mapped = _agent_map_xy(agent)
        if mapped is None:
            out.update(map_cones=None, map_precision=None, map_recall=None)
        else:
            precision, recall = map_precision_recall(mapped, track.cones_xy)
            out.update(map_cones=len(mapped), map_precision=precision, map_recall=recall)
        if score_detector and gts:
            from weather_gym.perception import evaluate as score

            res = score(gts, dets)
            out.update(det_map50=res.map50, det_recall=res.recall, det_frames=res.n_images)
        else:
            out.update(det_map50=None, det_recall=None, det_frames=0)
        wl = float(np.mean(w_lat)) if w_lat else 0.0
        dl = float(np.mean(d_lat)) if d_lat else 0.0
        out.update(weather_latency_ms=wl, detector_latency_ms=dl, added_latency_ms=wl + dl)
        return out
    finally:
        env.close()


# ----------------------------------------------------------------------------------------- the grid
def evaluate(config: EvalConfig, out_dir: str | Path, *, workers: int | None = None, backend: str = "process",
             ray_address: str | None = None, progress: bool = True, retry_failed: bool = True,
             report: bool = True, command: str | None = None, overwrite: bool = False) -> list[dict[str, Any]]:
    """Run the grid of ``config`` into ``out_dir/results.csv`` (resuming) and write the report.

    Returns this grid's rows (see :data:`METRICS`). ``out_dir/report.md`` and ``out_dir/plots/`` are
    rewritten from them when ``report`` is true; when ``out_dir`` holds no results.csv yet, an
    existing report or plot there is refused before any cell runs, unless ``overwrite``.
    """
    from weather_gym._io import derived_outputs_replaceable
    from weather_gym.evaluation.report import report_paths
    from weather_gym.evaluation.runner import check_results_path, run_cells

    cells = make_cells(config)
    out = Path(out_dir)
    results = check_results_path(out / "results.csv")
    replace = derived_outputs_replaceable(results, report_paths(out) if report else [], overwrite=overwrite)
    started = time.perf_counter()
    rows = run_cells(cells, run_cell, results, key_fields=CELL_KEY_FIELDS, workers=workers, backend=backend,
                     ray_address=ray_address, progress=progress, retry_failed=retry_failed, desc="evaluate")
    if report:
        from weather_gym.evaluation.report import write_report

        write_report(rows, out, config=config, wall_s=time.perf_counter() - started, command=command,
                     overwrite=replace)
    return rows


def config_summary(config: EvalConfig) -> dict[str, Any]:
    """JSON-friendly dict of a config (for reports)."""
    d = asdict(config)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}
