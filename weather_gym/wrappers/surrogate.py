"""``SurrogatePerceptionWrapper``: the detector's cone list in a weather, drawn from a statistical model.

Built on the render-free ground truth (``camera_images=False, ground_truth="geometry"``, the
``gt_cones`` path): no camera frame is rendered and no weather is drawn. Each step the visible cones
of ``info["gt"]`` go through :class:`~weather_gym.surrogate.sample.FrameSampler` with the model's
parameters for the current weather (``weather_gym.surrogate.model``; the shipped model by default),
giving the same observation as ``DetectorWrapper`` (``Dict(cones, mask, state)``) and the same
``info`` keys: ``info["detections"]`` (a ``ConeArrays`` of boxes, scores, classes, ranges,
bearings) and, when a weather is given, ``info["weather"]``.

**A still camera sees a still frame.** The detector is a deterministic function of the image: while
the car stands (same pose, same visible cones) under a weather whose frames do not change by
themselves (clear, the study's dim; not the per-frame droplets or the night camera's gain noise), the
real pipeline reports the same cones on
every frame, so a car that stopped because it saw nothing stays stopped. The surrogate does the
same: such a frame repeats the previous frame's detections (no new draw). Whether a weather's
frames change by themselves is probed once per weather: the effect applied to one test image for a
second of frames (:func:`frames_change_by_themselves`). The camera model's own sensor noise does not
count: it mostly jitters the boxes by a pixel or two and does not bring missed cones back (measured
with a standing car through the default camera: at low_light@2 the detector's list of one cone
changed twice in 55 frames; docs/surrogate.md).

The weather changes like the ``WeatherWrapper``'s: ``reset(options={"weather": spec})``,
``set_weather(spec)`` (through other wrappers: ``env.get_wrapper_attr("set_weather")(...)``; vector
envs: ``envs.call("set_weather", ...)``) or assigning ``weather``. An effect the model has no fit of
(the nominal presets: rain, fog, blur, ...) is modelled as clear weather, with a
``SurrogateFallbackWarning``, ``info["surrogate_fallback"]`` on every step and the ``fallback``
attribute saying so (docs/surrogate.md, "Nominal effects"). A weather the model cannot cover (k
beyond the fitted range, other parameters of a fitted effect, two fitted effects at once) is an
``InputError`` when it is set.

Any camera size: the model's box-height feature is the cone's box height at the detector's input
(``box_factor``: :func:`weather_gym.surrogate.camera.box_factor`), so a model fitted at 672x376
applies at 336x188 or 1280x720 (docs/surrogate.md, "Camera size").

Randomness: a child of the env's generator seeded at ``reset(seed=...)``: same seed, same bytes.

Example:
    >>> from weather_gym.pipeline import make_env
    >>> env = make_env(perception="surrogate", weather="droplets@3", max_episode_steps=50)
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs), obs["cones"].shape, env.unwrapped.renderer, info["weather"][0]["name"]
    (['cones', 'mask', 'state'], (64, 14), 'none', 'droplets')
    >>> env.close()
"""

from __future__ import annotations

import copy
import os
import time
import warnings
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import DEFAULT_MAX_CONES, cone_list_space, pack_cones
from weather_gym.surrogate.conditions import SurrogateFallbackWarning, fallback_note, split_nominal
from weather_gym.surrogate.model import SurrogateModel, load_model
from weather_gym.surrogate.sample import FrameSampler
from weather_gym.weather import current_spec, parse_weather, weather_source
from weather_gym.wrappers._recorded import recorded, unrecorded

__all__ = ["SurrogatePerceptionWrapper", "frames_change_by_themselves"]

_PROBE = np.random.default_rng(0).integers(0, 256, (48, 80, 3), dtype=np.uint8)
"""A fixed test image (a private generator with a constant seed: no global RNG)."""


def frames_change_by_themselves(effect: Any) -> bool:
    """Whether ``effect`` (a parsed weather) gives different frames from one unchanged image: it
    draws per frame (droplets), or evolves (persistent droplets grow): one second of frames (30) is
    probed, on a copy (``effect`` is untouched).

    Example:
        >>> from weather_gym.weather import parse_weather
        >>> frames_change_by_themselves(parse_weather("dim:0.9")), frames_change_by_themselves(parse_weather("droplets@2"))
        (False, True)
        >>> frames_change_by_themselves(parse_weather("low_light@2"))  # the night camera's gain noise
        True
    """

    probe = copy.deepcopy(effect)
    probe.reset(0)
    first = probe(_PROBE)
    return any(not np.array_equal(first, probe(_PROBE)) for _ in range(29))


def _warn_fallback(model: SurrogateModel, tables: Any) -> None:
    """Warn when ``tables`` has effects ``model`` has no fit of (once per effect and place: the text
    leaves out their k, and Python's default warning filter shows a text once)."""
    _, dropped = split_nominal(tables, model.conditions())
    if dropped:
        warnings.warn(fallback_note(dropped, with_k=False), SurrogateFallbackWarning, stacklevel=3)


class SurrogatePerceptionWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Replace the observation by a cone list drawn from the perception surrogate; see the module doc.

    Args:
        env: a ``ConeTrackEnv`` (possibly wrapped) whose info carries ``gt`` and ``camera`` and
            whose observation is a Dict with ``state``.
        weather: the weather to model (any spec; None: clear, and no ``info["weather"]``).
        model: a model path or a loaded ``SurrogateModel`` (None: the shipped one).
        max_cones: rows of the padded cone list.
        latency_in_info: put the surrogate's time per step in ``info["detector_latency_ms"]``.
    """

    def __init__(self, env: gym.Env, weather: Any = None, *, model: Any = None, max_cones: int = DEFAULT_MAX_CONES,
                 latency_in_info: bool = False) -> None:
        model = unrecorded(model)  # rebuilt from env.spec
        gym.utils.RecordConstructorArgs.__init__(self, _disable_deepcopy=True, weather=copy.deepcopy(weather),
                                                 model=recorded(model, (str, os.PathLike)), max_cones=max_cones,
                                                 latency_in_info=latency_in_info)
        gym.Wrapper.__init__(self, env)

        if not (isinstance(max_cones, int) and not isinstance(max_cones, bool) and max_cones >= 1):
            raise InputError(f"SurrogatePerceptionWrapper: max_cones must be an integer >= 1, got {max_cones!r}")
        inner = env.observation_space
        if not isinstance(inner, spaces.Dict) or "state" not in inner.spaces:
            raise InputError("SurrogatePerceptionWrapper needs an env whose observation is a Dict with a 'state' entry")
        if model is None or isinstance(model, str | os.PathLike):
            model = load_model(model)
        if not isinstance(model, SurrogateModel):
            raise InputError(f"SurrogatePerceptionWrapper: model must be a path or a SurrogateModel, got "
                             f"{type(model).__name__}")
        self.model = model
        camera = getattr(getattr(env.unwrapped, "config", None), "camera", None)
        self.camera = camera if isinstance(camera, CameraConfig) else CameraConfig()
        self.box_factor = model.box_factor(self.camera.width, self.camera.height)  # any camera size
        self.max_cones = max_cones
        self.latency_in_info = bool(latency_in_info)
        self.observation_space = spaces.Dict({**cone_list_space(max_cones).spaces, "state": inner["state"]})
        self._report_weather = weather is not None
        self._source = weather_source(weather)  # given / pool (the surrogate reads the pool presets)
        self._effect = parse_weather(weather)
        self._spec = current_spec(self._effect)
        point, self._fallback = model.resolve(self._spec)
        self.range_factor = model.range_factor(self.camera)
        self._sampler = FrameSampler(point, self.camera, box_factor=self.box_factor, fit_camera=model.camera_size,
                                     range_factor=self.range_factor)
        _warn_fallback(model, self._spec)
        self._weather_changes = frames_change_by_themselves(self._effect)  # probed once per weather
        self._view: tuple[bytes, bytes] | None = None
        self._rng: np.random.Generator | None = None
        self._step = 0
        self._latency = 0.0
        self._last: ConeArrays | None = None

    # -- weather -----------------------------------------------------------------------------
    @property
    def weather(self) -> Any:
        """The weather effect being modelled (assigning a spec calls ``set_weather``)."""
        return self._effect

    @weather.setter
    def weather(self, spec: Any) -> None:
        self.set_weather(spec)

    def set_weather(self, spec: Any) -> list[dict[str, Any]]:
        """Model ``spec`` from the next frame on; returns it as a list of effect tables."""
        effect = copy.deepcopy(parse_weather(spec))
        tables = current_spec(effect)
        point, fallback = self.model.resolve(tables)  # a weather the model cannot cover fails here
        self._source = weather_source(spec)
        self._sampler.set_point(point)
        self._fallback = fallback
        _warn_fallback(self.model, tables)
        self._weather_changes = frames_change_by_themselves(effect)
        self._view = None
        self._effect = effect
        self._spec = tables
        self._report_weather = True
        return [dict(t) for t in tables]

    @property
    def fallback(self) -> str | None:
        """None, or the note that the current weather has effects without a fit, modelled as clear weather
        (also ``info["surrogate_fallback"]`` on every step while it holds)."""
        return self._fallback

    @property
    def latency_ms(self) -> float:
        """Milliseconds the surrogate took on the last step."""
        return self._latency

    # -- episode -----------------------------------------------------------------------------
    def _convert(self, obs: dict, info: dict) -> tuple[dict, dict]:
        t0 = time.perf_counter()
        if "gt" not in info:
            raise InputError('SurrogatePerceptionWrapper needs info["gt"] (the visible cones) from the env')
        gt = info["gt"]
        view = None  # what a still frame repeats: the car's pose and the visible cones' boxes
        if not self._weather_changes and gt is not None and "pose" in info:
            view = (np.asarray(info["pose"], np.float64).tobytes(),
                    np.asarray(gt["boxes"]).tobytes() + np.asarray(gt["cone_ids"]).tobytes())
        if view is not None and view == self._view and self._last is not None:
            self._sampler.hold(gt, self._step)  # a still frame: the same detections (see the module doc)
        else:
            self._last = ConeArrays.trusted(self._sampler(gt, cast(np.random.Generator, self._rng), self._step))  # reset() drew it
        self._view = view
        det = self._last
        cones, mask = pack_cones(classes=det["classes"], ranges=det["ranges"], bearings=det["bearings"],
                                 scores=det["scores"], boxes=det["boxes"], camera=self.camera,
                                 max_cones=self.max_cones)
        self._step += 1
        out_info = dict(info)
        if self._report_weather:
            out_info["weather"] = [dict(t) for t in self._spec]  # nothing is drawn: the spec only changes when set
            out_info["weather_source"] = self._source  # as the WeatherWrapper says it
        out_info["detections"] = self._last
        if self._fallback is not None:
            out_info["surrogate_fallback"] = self._fallback
        self._latency = 1000.0 * (time.perf_counter() - t0)
        if self.latency_in_info:
            out_info["detector_latency_ms"] = self._latency
        return {"cones": cones, "mask": mask, "state": np.asarray(obs["state"], dtype=np.float32)}, out_info

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[Any, dict[str, Any]]:
        options = dict(options or {})
        if "weather" in options:
            self.set_weather(options.pop("weather"))
        obs, info = self.env.reset(seed=seed, options=options or None)
        if seed is not None or self._rng is None:
            self._rng = self.env.unwrapped.np_random.spawn(1)[0]
        self._sampler.reset()
        self._step = 0
        self._view = None
        return self._convert(obs, info)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        obs, info = self._convert(obs, info)
        return obs, reward, terminated, truncated, info
