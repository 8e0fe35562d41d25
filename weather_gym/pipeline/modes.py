"""Perception modes: what the agent observes, one registry entry per mode, carrying its properties.

A :class:`PerceptionMode` says how a mode wraps an env (``wrap``) and what it is: whether it renders
camera frames, takes weather, gives a cone list or an image, runs the detector, is scored per frame,
can record a video. :func:`weather_gym.pipeline.make_env`, ``weather-gym lap``, ``weather-gym
evaluate``, :func:`weather_gym.lab.evaluation.evaluate.run_cell` and ``weather-gym surrogate log`` ask
these properties, never a mode's name, so adding a mode is one :func:`register_mode` call here.

The shipped modes, in the order ``auto`` choices search them (:func:`auto_mode`):

* ``camera``    - no perception: ``Dict(image, depth, state)``, the (weathered) camera frame.
* ``detector``  - ``DetectorWrapper``: the cone detector on the (weathered) image -> ``Dict(cones, mask, state)``.
* ``oracle``    - ``GroundTruthConeWrapper`` on the rendered ground truth (pixel-exact visibility).
* ``gt_cones``  - ground-truth cones from geometry; the camera renders nothing (``camera_images=False,
  ground_truth="geometry"``): thousands of steps per second, for training controllers on cone lists.
* ``lidar``     - ``LidarConeWrapper``: the car's LiDAR (an HDL-32E by default; nothing rendered for the
  camera) through its own weather (``perception_kwargs={"lidar_weather": "fog:mor=60"}``) to cones of
  unknown colour (:mod:`weather_gym.wrappers.lidar`).
* ``fused``     - ``FusionWrapper`` on the ``detector`` stack: the camera's cones and the LiDAR's (an HDL-32E)
  fused, position from the LiDAR, colour from the camera (:mod:`weather_gym.wrappers.fusion`); camera
  weather as ``detector``, the LiDAR's through ``perception_kwargs={"lidar_weather": ...}``.
* ``surrogate`` - ``SurrogatePerceptionWrapper``: the ``gt_cones`` truth turned into what the shipped
  detector reports in the weather, drawn from a fitted model (:mod:`weather_gym.surrogate`).

Agents declare the observation keys they read (``weather_gym.agents.agent_observes``);
:func:`check_agent_observes` refuses a mode that does not give them.

Example:
    >>> from weather_gym.pipeline.modes import PERCEPTION_MODES, auto_mode, perception_mode
    >>> [m.name for m in PERCEPTION_MODES.values() if not m.renders_frames]
    ['gt_cones', 'surrogate', 'lidar']
    >>> auto_mode(frozenset({"cones", "mask", "state"})).name, auto_mode(frozenset()).name
    ('detector', 'camera')
    >>> perception_mode("sonar")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: unknown perception 'sonar'; valid: camera, detector, oracle, gt_cones, surrogate, lidar, fused
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import gymnasium as gym

from weather_gym.core._io import file_id
from weather_gym.core.errors import InputError, check_known
from weather_gym.core.registry import add_unique
from weather_gym.envs.config import LidarConfig
from weather_gym.perception.detector_spec import detector_id
from weather_gym.surrogate.model import SHIPPED_MODEL, load_model
from weather_gym.weather import parse_weather, to_spec
from weather_gym.wrappers import (
    DetectorWrapper,
    FusionWrapper,
    GroundTruthConeWrapper,
    LidarConeWrapper,
    SurrogatePerceptionWrapper,
    WeatherWrapper,
)
from weather_gym.wrappers.ground_truth import OracleNoise

__all__ = ["CONES", "IMAGE", "PERCEPTION_MODES", "PerceptionMode", "auto_mode", "check_agent_observes",
           "check_perception_kwargs", "default_mode", "detector_mode", "modes_where", "perception_mode",
           "register_mode"]

IMAGE = frozenset({"image", "depth", "state"})
"""The observation keys of a camera mode."""
CONES = frozenset({"cones", "mask", "state"})
"""The observation keys of a cone-list mode."""
RENDER_FREE: Mapping[str, Any] = {"camera_images": False, "ground_truth": "geometry"}
"""``EnvConfig`` overrides of a mode that renders nothing."""


@dataclass(frozen=True)
class PerceptionMode:
    """One perception mode and its properties.

    Attributes:
        name, doc: the mode's name (``--perception NAME``) and one line on what the agent observes.
        wrap: ``(env, weather, kwargs) -> env``: puts the mode's wrappers on a base env (``weather``:
            a weather spec or None; ``kwargs``: the perception wrapper's keywords).
        observation: the observation keys the agent gets.
        renders_frames: the camera renders images (False: ``env_overrides`` switch rendering off).
        takes_weather: weather acts on what the agent observes.
        is_scored: the detector's per-frame mAP is measured during an episode (``info["gt"]`` and
            ``info["detections"]`` of a real detector).
        can_record_video: ``--video`` / ``--strip`` can record the camera.
        gives_detections: ``info["detections"]`` with a detector's errors (``surrogate log`` records them).
        runs_detector: takes ``detector=`` (a model path or spec) and adds detector latency.
        wrapper: the perception wrapper class whose keywords ``perception_kwargs`` may hold (None: none).
        env_overrides: ``EnvConfig`` overrides the mode needs (e.g. :data:`RENDER_FREE`).
        record_kwargs: perception keywords that keep the camera image for a recording.
        fingerprint: ``kwargs -> {part: id}`` of the model files the mode runs with (results keys).
        takes_lidar_weather: the mode's wrapper takes ``lidar_weather`` (a LiDAR weather spec) among its keywords.
        check_weather: ``(kwargs, weather spec) -> None``, raising ``InputError`` for a weather the mode
            cannot produce (checked before a grid runs).
    """

    name: str
    doc: str
    wrap: Callable[[gym.Env, Any, dict[str, Any]], gym.Env]
    observation: frozenset[str]
    renders_frames: bool = True
    takes_weather: bool = True
    is_scored: bool = False
    can_record_video: bool = True
    gives_detections: bool = False
    runs_detector: bool = False
    wrapper: type | None = None
    env_overrides: Mapping[str, Any] = field(default_factory=dict)
    record_kwargs: Mapping[str, Any] = field(default_factory=dict)
    fingerprint: Callable[[Mapping[str, Any]], dict[str, str]] | None = None
    check_weather: Callable[[Mapping[str, Any], Any], None] | None = None
    takes_lidar_weather: bool = False

    def describe(self) -> str:
        """The doc line with what the mode cannot do (for ``--help``)."""
        notes = [] if self.renders_frames else ["nothing rendered (fast)"]
        notes += [] if self.takes_weather else ["no weather"]
        notes += [] if self.can_record_video else ["no video"]
        return self.doc + (f"; {', '.join(notes)}" if notes else "")


PERCEPTION_MODES: dict[str, PerceptionMode] = {}
"""Every perception mode by name, in registration order."""


def register_mode(mode: PerceptionMode) -> PerceptionMode:
    """Add ``mode`` (a name may be registered once)."""
    return add_unique(PERCEPTION_MODES, "perception mode", mode.name, mode)


def perception_mode(name: str | PerceptionMode) -> PerceptionMode:
    """The registered mode ``name`` (``InputError`` listing the valid ones)."""
    if isinstance(name, PerceptionMode):
        return name
    try:
        return PERCEPTION_MODES[name]
    except (KeyError, TypeError):
        raise InputError(f"unknown perception {name!r}; valid: {', '.join(PERCEPTION_MODES)}") from None


def modes_where(**properties: Any) -> list[str]:
    """Names of the modes whose attributes equal ``properties`` (``modes_where(renders_frames=False)``)."""
    return [m.name for m in PERCEPTION_MODES.values()
            if all(getattr(m, k) == v for k, v in properties.items())]


def default_mode() -> PerceptionMode:
    """The mode of an env made without ``perception`` (the first registered: the camera)."""
    return next(iter(PERCEPTION_MODES.values()))


def detector_mode() -> PerceptionMode:
    """The first mode that runs the detector (what ``detector=`` alone asks for)."""
    return next(m for m in PERCEPTION_MODES.values() if m.runs_detector)


def auto_mode(observes: Iterable[str] | None) -> PerceptionMode:
    """The first registered mode whose observation holds the keys ``observes`` (None: any mode)."""
    keys = frozenset(observes or ())
    for mode in PERCEPTION_MODES.values():
        if keys <= mode.observation:
            return mode
    raise InputError(f"no perception mode gives the observation keys {sorted(keys)}")


def check_agent_observes(agent: str, observes: Iterable[str] | None, mode: str | PerceptionMode) -> None:
    """``InputError`` when agent ``agent`` reads observation keys (``observes``) that ``mode`` does not give."""
    m = perception_mode(mode)
    missing = frozenset(observes or ()) - m.observation
    if missing:
        fits = [n for n, x in PERCEPTION_MODES.items() if frozenset(observes or ()) <= x.observation]
        raise InputError(f"agent {agent!r} reads obs[{', '.join(map(repr, sorted(missing)))}], which perception "
                         f"{m.name!r} does not give (it gives {', '.join(sorted(m.observation))}); perception "
                         f"modes for this agent: {', '.join(fits) or 'none'}")


# ------------------------------------------------------------------------------------ how modes wrap
def check_perception_kwargs(perception: str | PerceptionMode, kwargs: Mapping[str, Any], *, what: str,
                            error: type[InputError] = InputError) -> None:
    """Refuse keywords the mode's perception wrapper does not take (``what`` names where they were written),
    and bad oracle noise values, before anything is built.

    Example:
        >>> check_perception_kwargs("detector", {"bogus": 1}, what="scenario.toml [perception]")
        Traceback (most recent call last):
        ...
        weather_gym.core.errors.InputError: scenario.toml [perception]: DetectorWrapper (perception 'detector'): unknown argument(s) ['bogus']; ...
    """
    mode = perception_mode(perception)
    wrapper = mode.wrapper
    if wrapper is None:
        if kwargs:
            raise error(f"{what}: {sorted(kwargs)}: perception {mode.name!r} takes no arguments")
        return
    params = inspect.signature(wrapper.__init__).parameters  # type: ignore[misc]  # the wrapper class's own constructor
    found = dict(params)
    if wrapper is FusionWrapper:  # the detector's keywords go to the DetectorWrapper below it
        found = {**inspect.signature(DetectorWrapper.__init__).parameters, **found}
    allowed = {n for n, q in found.items() if q.kind in (q.POSITIONAL_OR_KEYWORD, q.KEYWORD_ONLY)}
    allowed -= {"self", "env", "weather"}
    noise = {}
    if wrapper is GroundTruthConeWrapper:  # OracleNoise fields as keywords
        noise = {k: v for k, v in kwargs.items() if k in {f.name for f in fields(OracleNoise)}}
        allowed |= {f.name for f in fields(OracleNoise)}
    check_known(kwargs, allowed, what=f"{what}: {wrapper.__name__} (perception {mode.name!r})", kind="argument",
                error=error)
    if noise:
        try:
            OracleNoise(**noise)
        except InputError as exc:
            raise error(f"{what}: {exc}") from None


def _has_images(env: gym.Env) -> bool:
    return isinstance(env.observation_space, gym.spaces.Dict) and "image" in env.observation_space.spaces


def _weathered(env: gym.Env, weather: Any, mode: str) -> gym.Env:
    """``env`` under a ``WeatherWrapper(weather)``; clear weather on an env without images is none."""
    if weather is None:
        return env
    effect = parse_weather(weather)  # a bad spec fails here, with the parser's message
    if _has_images(env):  # the spec itself, so the wrapper records where its k's came from
        return WeatherWrapper(env, weather=weather)
    if to_spec(effect):
        wet = [n for n, m in PERCEPTION_MODES.items() if m.takes_weather and n != mode]
        raise InputError(f"weather {weather!r} acts on camera images, and this env renders none (perception "
                         f"{mode!r}); take perception {', '.join(map(repr, wet))} to drive in weather")
    return env


def _no_kwargs(name: str, kwargs: Mapping[str, Any]) -> None:
    if kwargs:
        raise InputError(f"perception_kwargs {sorted(kwargs)} given, but perception {name!r} takes none")


def _wrap_camera(env: gym.Env, weather: Any, kwargs: dict[str, Any]) -> gym.Env:
    _no_kwargs("camera", kwargs)
    return _weathered(env, weather, "camera")


def _wrap_detector(env: gym.Env, weather: Any, kwargs: dict[str, Any]) -> gym.Env:
    if not _has_images(env):
        raise InputError("perception 'detector' needs camera images (camera_images=True)")
    # always a WeatherWrapper under the detector, so reset(options={"weather": ...}) and set_weather work
    return DetectorWrapper(_weathered(env, "clear" if weather is None else weather, "detector"), **kwargs)


def _wrap_ground_truth(name: str) -> Callable[[gym.Env, Any, dict[str, Any]], gym.Env]:
    def wrap(env: gym.Env, weather: Any, kwargs: dict[str, Any]) -> gym.Env:
        return GroundTruthConeWrapper(_weathered(env, weather, name), **kwargs)

    return wrap


def _wrap_surrogate(env: gym.Env, weather: Any, kwargs: dict[str, Any]) -> gym.Env:
    if _has_images(env):
        raise InputError("perception 'surrogate' renders nothing: build the env with camera_images=False, "
                         "ground_truth='geometry' (make_env does)")
    return SurrogatePerceptionWrapper(env, weather=weather, **kwargs)


def _surrogate_weather(kwargs: Mapping[str, Any], weather: Any) -> None:
    load_model(kwargs.get("model")).point(json.loads(weather) if isinstance(weather, str) else weather)


register_mode(PerceptionMode(
    "camera", "no perception: the (weathered) camera image, depth and state", _wrap_camera, IMAGE))
register_mode(PerceptionMode(
    "detector", "the cone detector on the (weathered) image -> cone list", _wrap_detector, CONES,
    is_scored=True, gives_detections=True, runs_detector=True, wrapper=DetectorWrapper,
    record_kwargs={"keep_image": True}, fingerprint=lambda kw: {"detector": detector_id(kw.get("detector"))}))
register_mode(PerceptionMode(
    "oracle", "the rendered frame's ground truth (pixel-exact visibility) -> cone list",
    _wrap_ground_truth("oracle"), CONES, wrapper=GroundTruthConeWrapper, record_kwargs={"keep_image": True}))
register_mode(PerceptionMode(
    "gt_cones", "ground-truth cones from geometry -> cone list, for training controllers",
    _wrap_ground_truth("gt_cones"), CONES, renders_frames=False, takes_weather=False, can_record_video=False,
    wrapper=GroundTruthConeWrapper, env_overrides=RENDER_FREE))
register_mode(PerceptionMode(
    "surrogate", "the detector's cone list in the weather, drawn from a fitted statistical model",
    _wrap_surrogate, CONES, renders_frames=False, can_record_video=False, gives_detections=True,
    wrapper=SurrogatePerceptionWrapper, env_overrides=RENDER_FREE,
    fingerprint=lambda kw: {"surrogate": file_id(kw.get("model") or SHIPPED_MODEL)},
    check_weather=_surrogate_weather))


def _wrap_lidar(env: gym.Env, weather: Any, kwargs: dict[str, Any]) -> gym.Env:
    if weather is not None and to_spec(parse_weather(weather)):
        raise InputError(f"weather {weather!r} acts on camera images; perception 'lidar' takes its own weather: "
                         "perception_kwargs={'lidar_weather': 'fog:mor=60+rain@2'} (weather-gym lap --lidar-weather)")
    wrapped: gym.Env = LidarConeWrapper(env, **kwargs)
    return wrapped


register_mode(PerceptionMode(
    "lidar", "the car's LiDAR through its weather -> cones of unknown colour (ground removal, clustering)",
    _wrap_lidar, CONES, renders_frames=False, can_record_video=False, wrapper=LidarConeWrapper, takes_lidar_weather=True,
    env_overrides={**RENDER_FREE, "lidar": LidarConfig()}))


def _wrap_fused(env: gym.Env, weather: Any, kwargs: dict[str, Any]) -> gym.Env:
    if not _has_images(env):
        raise InputError("perception 'fused' needs camera images (camera_images=True) and a LiDAR")
    kwargs = dict(kwargs)
    fusion_keys: dict[str, Any] = {k: kwargs.pop(k) for k in ("lidar_weather", "fusion", "cone_config", "min_gt_points")
                                   if k in kwargs}
    if "max_cones" in kwargs:
        fusion_keys["max_cones"] = kwargs["max_cones"]
    camera = DetectorWrapper(_weathered(env, "clear" if weather is None else weather, "fused"), **kwargs)
    return FusionWrapper(camera, **fusion_keys)


register_mode(PerceptionMode(
    "fused", "the detector's cones and the LiDAR's fused: LiDAR position, camera colour, noisy-OR confidence",
    _wrap_fused, CONES, is_scored=True, gives_detections=True, runs_detector=True, wrapper=FusionWrapper,
    takes_lidar_weather=True, can_record_video=False, env_overrides={"lidar": LidarConfig()},
    fingerprint=lambda kw: {"detector": detector_id(kw.get("detector"))}))
