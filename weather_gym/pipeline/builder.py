"""The one pipeline builder: env -> weather -> perception, for every caller.

``make_env`` is ``gymnasium.make`` with weather-gym's keywords (the registered entry point of every
``WeatherGym/*`` id is :func:`make_scenario_env`, which calls :func:`wrap_pipeline`), plus
:class:`~weather_gym.wrappers.EpisodeStatistics` outside Gymnasium's ``TimeLimit``. ``make_vec_env``
builds N of them in a Gymnasium vector env. The lap and evaluate commands, dataset rendering, the
benchmarks and the examples all build their envs here, so a policy is evaluated on exactly the
observation it was trained on.

Perception modes, i.e. what the agent observes, are the entries of
:data:`weather_gym.pipeline.modes.PERCEPTION_MODES` (``camera``, ``detector``, ``oracle``,
``gt_cones``, ``surrogate``); each entry says how it wraps the env (``PerceptionMode.wrap``) and what
the env must be (``env_overrides``: the render-free modes switch the camera off). ``oracle`` and
``gt_cones`` take ``OracleNoise`` fields in ``perception_kwargs`` (``miss_prob``, ...); ``surrogate``
takes ``model`` (a model path), ``max_cones``, ``latency_in_info``.

Example:
    >>> from weather_gym.pipeline import make_env
    >>> env = make_env("WeatherGym/ConeTrack-v0", perception="gt_cones", max_episode_steps=300)
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs), obs["cones"].shape, env.unwrapped.renderer
    (['cones', 'mask', 'state'], (64, 14), 'none')
    >>> env.close()
"""

from __future__ import annotations

import ast
import math
import multiprocessing
import os
import sys
import warnings
from collections.abc import Mapping
from functools import partial
from pathlib import Path
from types import FrameType
from typing import Any

import gymnasium as gym

from weather_gym.conditions import parse_state
from weather_gym.core.errors import FileFormatError, InputError, LimitError, StateError
from weather_gym.envs.checker import PassiveEnvCheckerSafeReset
from weather_gym.envs.cone_track import ConeTrackEnv
from weather_gym.envs.registration import check_env_id, scenario_of
from weather_gym.envs.scenario import Scenario, build_config, episode_steps, load_scenario
from weather_gym.pipeline.modes import (
    PERCEPTION_MODES,
    check_perception_kwargs,
    default_mode,
    detector_mode,
    perception_mode,
)
from weather_gym.pipeline.presets_default import default_presets
from weather_gym.weather import WeatherSpec
from weather_gym.weather.presets import DEFAULT_PRESETS
from weather_gym.wrappers import ConditionsWrapper, EpisodeStatistics

__all__ = ["DEFAULT_ENV_ID", "PERCEPTION_MODES", "make_env", "make_scenario_env", "make_vec_env", "wrap_pipeline"]

DEFAULT_ENV_ID = "WeatherGym/ConeTrack-v0"


def check_perception(perception: str) -> str:
    """``perception`` if it is a registered mode (:data:`PERCEPTION_MODES`), else an ``InputError`` listing them."""
    return perception_mode(perception).name


def wrap_pipeline(env: gym.Env, *, weather: Any = None, perception: str | None = None, detector: Any = None,
                  perception_kwargs: Mapping[str, Any] | None = None) -> gym.Env:
    """``env`` -> ``WeatherWrapper(weather)`` (when there is weather; always under a detector, clear
    by default, so the weather can change per episode) -> the ``perception`` wrapper: the mode's
    ``PerceptionMode.wrap`` (default: the first registered mode, the camera).

    ``detector`` is passed to ``DetectorWrapper`` as its ``detector`` argument (anything it accepts:
    a model path, a detector object, None for the shipped model); ``perception_kwargs`` are the
    perception wrapper's other keyword arguments.
    """
    mode = default_mode() if perception is None else perception_mode(perception)
    kwargs = dict(perception_kwargs or {})
    if detector is not None:
        if not mode.runs_detector:
            raise InputError(f"detector= is given but perception is {perception!r}; it needs " + " or ".join(
                f"perception={m.name!r}" for m in PERCEPTION_MODES.values() if m.runs_detector))
        if "detector" in kwargs:
            raise InputError("give the detector once: detector= or perception_kwargs['detector'], not both")
        kwargs["detector"] = detector
    return mode.wrap(env, weather, kwargs)


def _scenario_perception(sc: Scenario) -> tuple[str, Any, dict[str, Any]]:
    """The scenario's ``[perception]`` table as (mode, detector, wrapper keywords), checked against the
    mode's wrapper: an unknown mode or keyword is a :class:`FileFormatError` naming the file."""
    table = dict(sc.perception or {})
    mode = table.pop("mode", default_mode().name)
    detector = table.pop("detector", None)
    if sc.perception is not None:
        try:
            perception_mode(mode)
        except InputError as exc:
            raise FileFormatError(f"{sc.path} [perception] mode: {exc}") from None
        check_perception_kwargs(mode, table, what=f"{sc.path} [perception]", error=FileFormatError)
    return mode, detector, table


def make_scenario_env(scenario: str, render_mode: str | None = None, *, perception: str | None = None,
                      weather: Any = None, severity: int | None = None, detector: Any = None,
                      perception_kwargs: Mapping[str, Any] | None = None, env_checker: bool = False,
                      presets: Any = None,
                      **overrides: Any) -> gym.Env:
    """Entry point of the registered ids (``gym.make``): the scenario's env, weather and perception.

    Keywords: ``perception`` (a mode of :data:`PERCEPTION_MODES`; default: the scenario's, else
    ``camera``), ``weather`` (any weather spec, or a condition with ``severity``), ``detector`` and
    ``perception_kwargs`` (see :func:`wrap_pipeline`), ``presets`` (the presets file a ``CONDITION@SEVERITY``
    reads: None is the presets resolved for this env's scenario, :mod:`weather_gym.pipeline.presets_default`,
    unless ``$WEATHER_GYM_PRESETS`` is ``pool`` or a file; ``detector=True`` or a dict of
    ``DetectorWrapper`` keywords, the older form, mean ``perception="detector"`` with those keywords);
    the rest override the scenario's ``EnvConfig`` (``track=``, ``camera={"width": 336, "height":
    188}``, ``laps=``...). ``env_checker=True`` (what the registered ids pass) puts Gymnasium's passive
    env checker around the result, in the version that survives a refused first reset
    (:class:`~weather_gym.envs.checker.PassiveEnvCheckerSafeReset`).
    """

    sc = load_scenario(scenario)
    sc_mode, sc_detector, sc_kwargs = _scenario_perception(sc)
    if detector is True or isinstance(detector, Mapping):  # the older form: detector=True / a dict of wrapper kwargs
        table = {} if detector is True else dict(detector)
        if table.pop("enabled", True) is False:
            perception, detector = perception or default_mode().name, None
        else:
            perception = perception or detector_mode().name
            detector = table.pop("detector", None)
            perception_kwargs = {**table, **dict(perception_kwargs or {})}
    if perception is None:
        perception = detector_mode().name if detector is not None and sc_mode == default_mode().name else sc_mode
    mode = perception_mode(perception)
    if perception == sc_mode:
        detector = sc_detector if detector is None else detector
        perception_kwargs = {**sc_kwargs, **dict(perception_kwargs or {})}
    overrides = {**mode.env_overrides, **overrides}
    config = build_config(sc, overrides)
    env: gym.Env = ConeTrackEnv(config, render_mode=render_mode)
    try:
        spec = _weather_spec(sc, weather, severity)
        if presets == "pool":
            presets = DEFAULT_PRESETS
        elif presets in (None, "resolved") and not isinstance(spec, WeatherSpec):
            # the default: resolved for this env where its frames go through the weather (the surrogate's
            # table holds the pool presets' k's; ground truth and LiDAR see no camera weather)
            images = mode.renders_frames and mode.takes_weather
            presets = default_presets(spec, config, detector if mode.runs_detector else None,
                                      force=presets == "resolved") if images else None
        if presets is not None and spec is not None:
            spec = WeatherSpec(spec, str(presets))
        env = wrap_pipeline(env, weather=spec, perception=perception, detector=detector,
                            perception_kwargs=perception_kwargs)
        return PassiveEnvCheckerSafeReset(env) if env_checker else env
    except BaseException:
        env.close()
        raise


def _weather_spec(sc: Scenario, weather: Any, severity: int | None) -> Any:
    if weather is None and severity is None:
        if not sc.weather:
            return None
        if "spec" in sc.weather:
            return sc.weather["spec"]
        return (sc.weather["condition"], int(sc.weather.get("severity", 0)))
    if severity is not None:
        if not isinstance(weather, str):
            raise InputError(f"severity= needs weather= to be a condition name (e.g. 'low_light'), got {weather!r}")
        return (weather, int(severity))
    return weather


def make_env(env_id: str = DEFAULT_ENV_ID, *, perception: str | None = None, weather: Any = None,
             severity: int | None = None, detector: Any = None, perception_kwargs: Mapping[str, Any] | None = None,
             max_episode_steps: int | None = None, max_episode_s: float | None = None,
             episode_statistics: bool = True, render_mode: str | None = None, presets: Any = None,
             conditions: Any = None, **env_kwargs: Any) -> gym.Env:
    """One env: ``gym.make(env_id, ...)`` (env -> weather -> perception, ``TimeLimit``) ->
    ``EpisodeStatistics`` (``info["episode"]`` at the end of each episode).

    Args:
        env_id: a registered ``WeatherGym/*`` id.
        perception: a mode of :data:`PERCEPTION_MODES` (default: the scenario's, else ``camera``).
        weather: any weather spec (``"droplets@3"``, ``{"dim": 0.5}``, an effect...), or a condition
            name with ``severity``.
        detector: the ``DetectorWrapper``'s detector (perception ``detector``): a model path, a
            detector object, or None for the shipped model.
        perception_kwargs: the perception wrapper's other keywords (``max_cones``, ``score_threshold``,
            ``keep_image``, ``OracleNoise`` fields...).
        max_episode_steps: the ``TimeLimit`` in steps (default: ``max_episode_s`` at the env's control rate).
        max_episode_s: the time limit in simulated seconds (default: the scenario's, 100 s): the
            ``TimeLimit`` is ``max_episode_s * control_hz`` steps, so ``sim={"control_hz": 60}`` gets
            twice the steps of 30 Hz. Give this or ``max_episode_steps``, not both.
        episode_statistics: add :class:`~weather_gym.wrappers.EpisodeStatistics`.
        presets: the presets file that ``CONDITION@SEVERITY`` weather reads. Default: resolved for this
            env's track, world, camera and detector (cached; minutes the first time a scenario is used;
            :mod:`weather_gym.pipeline.presets_default`), unless ``$WEATHER_GYM_PRESETS`` is ``pool`` (the
            shipped pool presets) or a file (docs/calibration.md). ``info["weather_source"]`` says which
            one a frame's k came from.
        conditions: one physical weather state for the camera, the LiDAR and the tyres
            (``"rain:8mm/h+fog:60m"``, :mod:`weather_gym.conditions`): a
            :class:`~weather_gym.wrappers.ConditionsWrapper` on top; not with ``weather`` or a ``lidar_weather``.
        env_kwargs: ``EnvConfig`` overrides (``track``, ``laps``, ``camera``, ``sim``, ...).
    """

    check_env_id(env_id)
    kwargs: dict[str, Any] = dict(env_kwargs)
    if conditions is not None:
        parse_state(conditions)  # a bad spec fails before anything is built
        if weather is not None or severity is not None or "lidar_weather" in (perception_kwargs or {}):
            raise InputError("give the weather once: conditions= (one state for every sensor and the tyres) or "
                             "weather= / perception_kwargs['lidar_weather'], not both")
        if perception == "surrogate":
            raise InputError("conditions= does not reach perception 'surrogate' (its model is fitted to named camera "
                             "effects); take perception 'detector', 'lidar' or 'fused'")
        weather = "clear"  # a WeatherWrapper under camera stacks, for the conditions' camera effects
    for key, value in (("perception", perception), ("weather", weather), ("severity", severity),
                       ("detector", detector), ("perception_kwargs", perception_kwargs),
                       ("render_mode", render_mode), ("presets", None if presets is None else str(presets))):
        if value is not None:
            kwargs[key] = value
    if max_episode_steps is not None:
        if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int) or max_episode_steps < 1:
            raise InputError(f"max_episode_steps must be an integer >= 1, got {max_episode_steps!r}")
        kwargs["max_episode_steps"] = max_episode_steps
        if max_episode_s is not None:
            raise InputError("give max_episode_steps or max_episode_s, not both")
    else:
        steps = _time_limit_steps(env_id, env_kwargs.get("sim"), max_episode_s)
        if steps is not None:
            kwargs["max_episode_steps"] = steps
    env = gym.make(env_id, **kwargs)
    if conditions is not None:
        env = ConditionsWrapper(env, conditions)
    if episode_statistics:
        env = EpisodeStatistics(env)
    return env


def _time_limit_steps(env_id: str, sim: Any, max_episode_s: float | None) -> int | None:
    """The ``TimeLimit`` of ``env_id`` in steps when it differs from the registered one: ``max_episode_s``
    (default: the scenario's) at the control rate of ``sim`` (a ``SimConfig`` or a dict of its fields)."""

    if max_episode_s is not None and (isinstance(max_episode_s, bool) or not isinstance(max_episode_s, int | float)
                                      or not math.isfinite(max_episode_s) or max_episode_s <= 0):
        raise InputError(f"max_episode_s must be a number of seconds > 0, got {max_episode_s!r}")
    if not env_id.startswith("WeatherGym/"):
        return None
    sc = scenario_of(env_id)
    hz = sim.get("control_hz") if isinstance(sim, Mapping) else getattr(sim, "control_hz", None)
    if isinstance(hz, bool) or not isinstance(hz, int | float) or not math.isfinite(hz) or hz <= 0:
        hz = sc.control_hz  # none given (a bad one fails in the env's config, with its message)
    if max_episode_s is None and float(hz) == sc.control_hz:
        return None  # the registered limit
    return episode_steps(sc.max_episode_s if max_episode_s is None else max_episode_s, hz)


MAX_SYNC_ENVS = 64
"""Most envs :func:`make_vec_env` builds in one process (``"sync"``); ``"async"`` allows 4 per CPU core."""


def start_method(context: str | None, caller: str = "make_vec_env") -> str | None:
    """``context``, or ``"fork"`` where a ``spawn``/``forkserver`` worker would re-run unguarded script code
    (with a ``RuntimeWarning`` naming ``caller`` and the line; a ``StateError`` where there is no fork)."""

    method = context if context is not None else multiprocessing.get_start_method()
    if method not in ("spawn", "forkserver"):
        return context
    where = unguarded_main_call()
    if where is None:
        return context
    if "fork" not in multiprocessing.get_all_start_methods():
        raise StateError(f"{caller} is called at {where}, outside `if __name__ == \"__main__\":`; "
                         f"{method} workers import that script and would run it again: put the call "
                         "under the guard")
    warnings.warn(f"{caller} is called at {where}, outside `if __name__ == \"__main__\":`, where "
                  f"{method} workers would run the script again: starting them with fork instead (put "
                  "the call under the guard to keep forkserver)", RuntimeWarning, stacklevel=3)
    return "fork"


def unguarded_main_call() -> str | None:
    """``"FILE:LINE"`` of the top-level statement of the ``__main__`` script that is running now, when
    it is not under ``if __name__ == "__main__":`` (code a ``spawn``/``forkserver`` worker re-runs);
    None when guarded, not called from a script's top level, or the source cannot be read.

    Example:
        >>> unguarded_main_call() is None  # doctest's own __main__ guards its code
        True
    """

    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or not path:
        return None  # interactive / python -c: workers do not import a script
    frame: FrameType | None = sys._getframe(1)
    while frame is not None and not (frame.f_globals is vars(main) and frame.f_code.co_name == "<module>"):
        frame = frame.f_back
    if frame is None:
        return None
    line = frame.f_lineno
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return None
    for node in tree.body:
        if node.lineno <= line <= (node.end_lineno or node.lineno):
            return None if _is_main_guard(node) else f"{path}:{line}"
    return None


def _is_main_guard(node: ast.stmt) -> bool:
    if not (isinstance(node, ast.If) and isinstance(node.test, ast.Compare) and len(node.test.ops) == 1
            and isinstance(node.test.ops[0], ast.Eq)):
        return False
    sides = [node.test.left, *node.test.comparators]
    return (any(isinstance(x, ast.Name) and x.id == "__name__" for x in sides)
            and any(isinstance(x, ast.Constant) and x.value == "__main__" for x in sides))


def make_vec_env(env_id: str = DEFAULT_ENV_ID, num_envs: int = 2, *, vectorization_mode: str = "async",
                 context: str | None = "forkserver", vector_kwargs: Mapping[str, Any] | None = None,
                 **make_kwargs: Any) -> gym.vector.VectorEnv:
    """``num_envs`` envs of :func:`make_env` (same keywords) in a Gymnasium vector env.

    ``vectorization_mode`` ``"async"`` (one process per env) or ``"sync"``. Async workers start with
    ``context`` (``forkserver`` by default: a fresh process that keeps the EGL renderer; see
    :mod:`weather_gym.sim.renderer`). Seed with ``reset(seed=s)``: env i gets ``s + i``.

    A ``forkserver`` or ``spawn`` worker imports the script that started it, so in a script the call
    belongs under ``if __name__ == "__main__":``. Called from a script's top level outside that guard
    (where each worker would run the script again, and the workers die), the workers start with
    ``fork`` instead, with a ``RuntimeWarning`` naming the line; where there is no ``fork``, a
    ``StateError`` says to add the guard.
    """

    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise InputError(f"num_envs must be an integer >= 1, got {num_envs!r}")
    if vectorization_mode not in ("sync", "async"):
        raise InputError(f"vectorization_mode must be 'sync' or 'async', got {vectorization_mode!r}")
    most = 4 * (os.cpu_count() or 1) if vectorization_mode == "async" else MAX_SYNC_ENVS
    if num_envs > most:
        raise LimitError(f"num_envs must be at most {most} ({'4 worker processes per CPU core' if vectorization_mode == 'async' else 'envs in one process'} "
                         f"with vectorization_mode={vectorization_mode!r}), got {num_envs}")
    make_env(env_id, **make_kwargs).close()  # a bad setting fails here, in this process, with its message
    fns = [partial(make_env, env_id, **make_kwargs) for _ in range(num_envs)]
    vk = dict(vector_kwargs or {})
    if vectorization_mode == "sync":
        return gym.vector.SyncVectorEnv(fns, **vk)
    if vectorization_mode == "async":
        if context is not None:
            vk.setdefault("context", context)
        vk["context"] = start_method(vk.get("context"))
        return gym.vector.AsyncVectorEnv(fns, **vk)
    raise InputError(f"vectorization_mode must be 'sync' or 'async', got {vectorization_mode!r}")
