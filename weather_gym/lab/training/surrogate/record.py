"""Drive full-pipeline (or surrogate) episodes and log what perception reported: ``weather-gym surrogate log``.

The log format, the matching of detections to true cones and the per-frame tables are in
:mod:`weather_gym.surrogate.log`; this module drives the episodes (the pipeline builder and the
episode driver), so it sits above them, like the evaluation.

Example:
    >>> from weather_gym.lab.training.surrogate.record import record
    >>> log = record(tracks=["small_track"], weathers=["clear"], seeds=[0], steps=5)   # doctest: +SKIP

The surrogate's own tables (nothing rendered, a few milliseconds a step):
    >>> log = record(tracks=["small_track"], weathers=["clear"], seeds=[0], steps=3, perception="surrogate")
    >>> len(log), log.episodes[0]["steps"]
    (4, 3)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict
from typing import Any, cast

from weather_gym.agents import agent_observes, make_agent
from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError
from weather_gym.envs.cone_track import ConeTrackEnv
from weather_gym.perception.detector_spec import detector_id
from weather_gym.pipeline import make_env
from weather_gym.pipeline.episode import run_episode
from weather_gym.pipeline.modes import check_agent_observes, detector_mode, modes_where, perception_mode
from weather_gym.surrogate.conditions import condition_of
from weather_gym.surrogate.log import (
    _TABLES,
    CONE_COLUMNS,
    FP_COLUMNS,
    FRAME_COLUMNS,
    IOU_MATCH,
    LOG_SCHEMA,
    SurrogateLog,
    _Recorder,
    _stack,
)
from weather_gym.weather import current_spec

__all__ = ["loggable_modes", "record"]


def record(*, tracks: Sequence[str], weathers: Sequence[Any], seeds: Sequence[int], steps: int,
           detector: Any = None, env_kwargs: dict[str, Any] | None = None, perception: str | None = None,
           agent: str = "gt_pure_pursuit", perception_kwargs: dict[str, Any] | None = None,
           progress: Callable[[str], None] | None = None) -> SurrogateLog:
    """Drive ``steps`` steps (at most) per (track, weather, seed) and log them.

    ``perception``: a mode that gives ``info["detections"]`` (``PerceptionMode.gives_detections``):
    ``detector`` (the full pipeline, the default) or ``surrogate`` (the same tables from the
    surrogate, for validation). ``agent``: the driver (``gt_pure_pursuit``: the true
    track; ``mapper_pure_pursuit``: drives on the cone list it receives). ``detector``: the
    ``DetectorWrapper``'s detector (None: the shipped model). ``env_kwargs``: further ``EnvConfig``
    overrides (``camera=...``). Each episode's lap metrics are kept in ``episodes``.
    """
    mode = detector_mode() if perception is None else perception_mode(perception)
    if not mode.gives_detections:
        raise InputError(f"surrogate log: perception must be one of {', '.join(map(repr, loggable_modes()))} "
                         f"(a mode that reports detections), got {mode.name!r}")
    check_agent_observes(agent, agent_observes(agent), mode)

    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise InputError(f"steps must be an integer >= 1, got {steps!r}")
    if not tracks or not weathers or not seeds:
        raise InputError("surrogate log needs at least one track, one weather and one seed")
    for w in weathers:
        condition_of(w)  # two effects at once fail before any driving
    parts: list[_Recorder] = []
    episodes: list[dict[str, Any]] = []
    camera_cfg = None
    det_input = None
    for track in tracks:
        for weather in weathers:
            # a rendering mode takes the geometric ground truth too, so both modes log the same truth
            extra: dict[str, Any] = {"ground_truth": "geometry"} if mode.renders_frames else {}
            if mode.runs_detector:
                extra["detector"] = detector
            env = make_env(perception=mode.name, weather=weather, track=track, max_episode_steps=steps,
                           perception_kwargs=perception_kwargs, **extra, **dict(env_kwargs or {}))
            try:
                base = cast(ConeTrackEnv, env.unwrapped)
                camera_cfg = base.config.camera
                if mode.runs_detector:
                    det_input = _detector_input(env.get_wrapper_attr("detector"), camera_cfg)
                for seed in seeds:
                    rec = _Recorder(len(episodes), camera_cfg)
                    driver = make_agent(agent, base.track, camera_cfg)
                    res = run_episode(env, driver, seed=int(seed), on_step=rec)
                    spec = env.get_wrapper_attr("weather")

                    cond, k = condition_of(weather)
                    episodes.append({"track": str(track), "weather": current_spec(spec), "condition": cond, "k": k,
                                     "seed": int(seed), "steps": int(res.steps), "end": res.end_reason, "agent": agent,
                                     "perception": mode.name, "completed": bool(res.completed),
                                     "lap_time_s": res.lap_times_s[0] if res.lap_times_s else None,
                                     "cones_hit": int(res.cones_hit), "cte_mean_m": float(res.cte_mean_m),
                                     "progress": float(res.progress)})
                    parts.append(rec)
                    if progress is not None:
                        progress(f"{track} {weather} seed {seed}: {res.steps} steps, "
                                 f"{int(sum(len(x) for x in rec.cones['episode']))} cone rows, "
                                 f"{int(sum(len(x) for x in rec.fps['episode']))} false positives")
            finally:
                env.close()
    merged = {name: {k: [x for r in parts for x in getattr(r, name)[k]] for k in cols} for name, cols in _TABLES.items()}
    meta = {"schema": LOG_SCHEMA, "camera": _camera_dict(camera_cfg), "detector": _detector_name(detector),
            "iou": IOU_MATCH, **({"detector_input": det_input} if det_input else {})}
    return SurrogateLog(_stack(merged["cones"], CONE_COLUMNS), _stack(merged["fps"], FP_COLUMNS),
                        _stack(merged["frames"], FRAME_COLUMNS), episodes, meta)


def loggable_modes() -> list[str]:
    """The perception modes a surrogate log can record (those that report detections)."""
    return modes_where(gives_detections=True)


def _detector_input(detector: Any, camera: CameraConfig) -> list[int] | None:
    """The detector's input (W, H) for this camera's frames (None: it does not say)."""
    rule = getattr(detector, "input_size_for", None)
    size = rule(camera.width, camera.height) if callable(rule) else getattr(detector, "input_size", None)
    return [int(size[0]), int(size[1])] if size is not None else None


def _detector_name(detector: Any) -> str:
    if detector is None:
        try:
            return f"shipped:{detector_id(None)}"
        except Exception:  # noqa: BLE001 - only a label
            return "shipped"
    return str(detector)


def _camera_dict(camera: CameraConfig | None) -> dict[str, Any]:
    if camera is None:
        return {}

    return {k: v for k, v in asdict(camera).items() if isinstance(v, int | float | str | bool)}
