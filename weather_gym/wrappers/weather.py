"""``WeatherWrapper``: weather on the image observations of any Gymnasium env.

Works on an env whose observation is an image ``Box(0, 255, (H, W, 3), uint8)`` or a ``Dict`` with
such an image under ``image_key``; with a ``depth_key`` entry (metres) it is passed to the effects
(fog, motion blur), and a ``state_key`` vector is read as ``state_fields`` (speed, yaw rate, ...).
The observation space is unchanged.

The weather is anything :func:`~weather_gym.weather.parse_weather` accepts (an effect, a
``Compose``, a ``Ramp`` for weather that changes over the episode, ``{"droplets": 0.55}``,
``"low_light@2"``, ...) and can be changed for the next episode with
``reset(options={"weather": spec})`` (the other options go to the wrapped env).

Each episode is a run of the weather (``weather.start(seed)``, an
:class:`~weather_gym.weather.EffectRun`): the weather object itself is never changed, so one
object can serve several envs. Randomness: the wrapper's own generator, derived from the reset seed (a ``SeedSequence`` child
of ``seed``, distinct from the env's own stream); ``reset(seed=None)`` continues the sequence, or
on the first reset starts from the env's ``np_random_seed``. Same seeds, same frames: same bytes.

**Changing the weather mid-episode**: ``set_weather(spec)`` (or assigning ``weather``) takes effect
from the next frame, with a fresh random stream derived from the episode's seed (same calls, same
bytes). It works through any wrappers above and on vector envs::

    env.get_wrapper_attr("set_weather")("rain@2")        # through DetectorWrapper, TimeLimit, ...
    envs.call("set_weather", "fog@3")                     # every env of a gymnasium VectorEnv
    envs.set_attr("weather", ["clear", "droplets@4"])     # one spec per env
    vec_env.env_method("set_weather", "low_light@2")      # stable-baselines3 VecEnv

``info["weather"]`` is the spec applied to the frame (a ramp's current k); ``info["weather_source"]`` says
where its k's came from: ``"given"`` (written out in the spec), ``"pool"`` (a ``CONDITION@SEVERITY`` read
from the shipped presets, calibrated on the pool of tracks), ``"resolved"`` (from a presets file resolved
for this scenario, ``presets=`` or ``$WEATHER_GYM_PRESETS``; docs/calibration.md) or ``"file"``. The time the weather
added to the last step is ``wrapper.latency_ms``; it goes into ``info["weather_latency_ms"]`` only
with ``latency_in_info=True`` (a wall-clock time differs between identical runs, so by default the
info stays deterministic). With ``render_mode="rgb_array"`` and a camera ``render_view`` below
(``ConeTrackEnv``'s ``render_view="camera"``), ``render()`` returns the weathered frame the agent
saw, so videos (Gymnasium's ``RecordVideo``, ``weather_gym.wrappers.RecordVideo``) show the weather.

Example:
    >>> import gymnasium as gym, numpy as np
    >>> from weather_gym.wrappers import WeatherWrapper
    >>> class Camera(gym.Env):
    ...     observation_space = gym.spaces.Box(0, 255, (48, 64, 3), np.uint8)
    ...     action_space = gym.spaces.Discrete(1)
    ...     def reset(self, *, seed=None, options=None):
    ...         super().reset(seed=seed); return np.full((48, 64, 3), 150, np.uint8), {}
    ...     def step(self, action):
    ...         return np.full((48, 64, 3), 150, np.uint8), 0.0, False, False, {}
    >>> env = WeatherWrapper(Camera(), weather={"dim": 0.5})
    >>> obs, info = env.reset(seed=0)
    >>> int(obs[0, 0, 0]), info["weather"][0]["name"]
    (75, 'dim')
"""

from __future__ import annotations

import copy
import time
from collections.abc import Mapping, Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from weather_gym.core.errors import InputError
from weather_gym.weather import Effect, EffectRun, WeatherSpec, current_spec, parse_weather, weather_source

__all__ = ["STATE_FIELDS", "WeatherWrapper"]

#: Default meaning of the entries of the observation's state vector (``ConeTrackEnv``).
STATE_FIELDS = ("speed", "yaw_rate", "odom_x", "odom_y", "odom_yaw")

# spawn key that separates the weather's random stream from the env's own for the same seed
_SPAWN_KEY = (0x57EA7E7,)


def _check_image_space(space: Any, where: str) -> None:
    if not (isinstance(space, spaces.Box) and space.dtype == np.uint8 and len(space.shape) == 3
            and space.shape[2] == 3):
        raise InputError(f"WeatherWrapper: {where} must be an image Box(0, 255, (H, W, 3), uint8), got {space}")


class WeatherWrapper(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Apply weather to image observations; see the module doc."""

    def __init__(self, env: gym.Env, weather: Any = None, *, image_key: str = "image",
                 depth_key: str | None = "depth", state_key: str | None = "state",
                 state_fields: Sequence[str] = STATE_FIELDS, fx: float | None = None,
                 render_weather: bool | None = None, latency_in_info: bool = False,
                 presets: str | None = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, weather=weather, image_key=image_key, depth_key=depth_key, state_key=state_key,
            state_fields=state_fields, fx=fx, render_weather=render_weather, latency_in_info=latency_in_info,
            presets=presets)
        given: Any = weather.presets if isinstance(weather, WeatherSpec) and presets is None else presets
        self.presets = None if given is None else str(given)
        gym.ObservationWrapper.__init__(self, env)
        self.latency_in_info = bool(latency_in_info)
        space = env.observation_space
        self.image_key = image_key
        if isinstance(space, spaces.Dict):
            if image_key not in space.spaces:
                raise InputError(f"WeatherWrapper: observation Dict has no image key {image_key!r} "
                                 f"(keys: {', '.join(space.spaces)}); pass image_key=...")
            _check_image_space(space[image_key], f"observation[{image_key!r}]")
            self._is_dict = True
            self.depth_key = depth_key if depth_key in space.spaces else None
            self.state_key = state_key if state_key in space.spaces else None
        else:
            _check_image_space(space, "the observation")
            self._is_dict = False
            self.depth_key = self.state_key = None
        self.state_fields = tuple(state_fields)
        if fx is not None and not (np.isfinite(fx) and fx > 0):
            raise InputError(f"WeatherWrapper: fx must be a positive focal length in pixels, got {fx!r}")
        self.fx = fx
        self._weather: Effect = parse_weather(weather, self.presets)
        self.weather_source = weather_source(weather, self.presets)
        self._run: EffectRun | None = None  # the weather's episode, started on reset
        self._ss: np.random.SeedSequence | None = None
        self._rng: np.random.Generator | None = None
        self._latency_ms = 0.0
        if render_weather is None:  # the camera view of the env below is what the agent sees
            render_weather = getattr(env.unwrapped, "render_view", None) == "camera"
        self.render_weather = bool(render_weather)
        self._last_image: np.ndarray | None = None

    @property
    def latency_ms(self) -> float:
        """Milliseconds the weather took on the last frame."""
        return self._latency_ms

    @property
    def run(self) -> EffectRun | None:
        """The weather's run of this episode (its generator and state; None before the first reset)."""
        return self._run

    @property
    def weather(self) -> Effect:
        """The weather effect applied to the observations (assigning a spec calls ``set_weather``)."""
        return self._weather

    @weather.setter
    def weather(self, spec: Any) -> None:
        self.set_weather(spec)

    def set_weather(self, spec: Any) -> list[dict[str, Any]]:
        """Change the weather from the next frame on, mid-episode or between episodes.

        ``spec`` is anything :func:`~weather_gym.weather.parse_weather` takes (``"rain@2"``,
        ``{"fog": 0.4}``, an effect, ``"clear"``...); an effect object is copied, and each env keeps
        its own run of it, so one object given to several envs (``VectorEnv.call``) never shares
        state. The new weather's random
        stream is the next child of the episode's seed sequence: the same calls at the same steps
        give the same bytes. Returns the new weather as a spec (``to_spec``-style list of tables).

        Example:
            >>> import gymnasium as gym, numpy as np
            >>> from weather_gym.wrappers import WeatherWrapper
            >>> class Camera(gym.Env):
            ...     observation_space = gym.spaces.Box(0, 255, (8, 8, 3), np.uint8)
            ...     action_space = gym.spaces.Discrete(1)
            ...     def reset(self, *, seed=None, options=None):
            ...         super().reset(seed=seed); return np.full((8, 8, 3), 200, np.uint8), {}
            ...     def step(self, action):
            ...         return np.full((8, 8, 3), 200, np.uint8), 0.0, False, False, {}
            >>> env = gym.wrappers.TimeLimit(WeatherWrapper(Camera()), max_episode_steps=10)
            >>> _ = env.reset(seed=0)
            >>> env.get_wrapper_attr("set_weather")({"dim": 0.5})[0]["k"]
            0.5
            >>> int(env.step(0)[0][0, 0, 0])
            100
        """
        effect = copy.deepcopy(parse_weather(spec, self.presets))
        self.weather_source = weather_source(spec, self.presets)
        if self._ss is not None:  # inside an episode: a fresh, repeatable stream for the new weather
            self._run = effect.start(self._ss.spawn(1)[0])
        self._weather = effect
        return current_spec(self._run if self._run is not None else effect)

    # -- episode -----------------------------------------------------------------------------
    def _seed_episode(self, seed: int | None) -> None:
        if seed is not None:
            self._ss = np.random.SeedSequence(seed, spawn_key=_SPAWN_KEY)
        elif self._ss is None:
            base = getattr(self.env, "np_random_seed", None)
            self._ss = (np.random.SeedSequence(int(base), spawn_key=_SPAWN_KEY)
                        if isinstance(base, int | np.integer) and base >= 0 else np.random.SeedSequence())
        rng_ss, effect_ss = self._ss.spawn(1)[0].spawn(2)
        self._rng = np.random.default_rng(rng_ss)
        self._run = self._weather.start(effect_ss)

    def _episode_run(self) -> EffectRun:
        if self._run is None:  # observation() called before any reset: the default episode
            self._run = self._weather.start(None)
        return self._run

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        options = dict(options or {})
        if "weather" in options:
            spec = options.pop("weather")
            self._weather = parse_weather(spec, self.presets)
            self.weather_source = weather_source(spec, self.presets)
        obs, info = self.env.reset(seed=seed, options=options or None)
        self._seed_episode(seed)
        obs = self.observation(obs)
        return obs, self._info(info)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        obs = self.observation(obs)
        return obs, reward, terminated, truncated, self._info(info)

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        out = {**info, "weather": current_spec(self._run if self._run is not None else self._weather),
               "weather_source": self.weather_source}
        if self.latency_in_info:
            out["weather_latency_ms"] = self._latency_ms
        return out

    # -- observation -------------------------------------------------------------------------
    def _state(self, obs: Mapping[str, Any]) -> dict[str, float] | None:
        state: dict[str, float] = {}
        if self.state_key is not None:
            raw = obs[self.state_key]
            if isinstance(raw, Mapping):
                state.update(raw)
            else:
                vec = np.asarray(raw, dtype=np.float64).ravel()
                state.update({f: float(v) for f, v in zip(self.state_fields, vec, strict=False)})
        if self.fx is not None:
            state["fx"] = self.fx
        return state or None

    def observation(self, observation: Any) -> Any:
        t0 = time.perf_counter()
        if self._is_dict:
            depth = observation[self.depth_key] if self.depth_key is not None else None
            image = self._episode_run()(observation[self.image_key], depth=depth,
                                        state=self._state(observation), rng=self._rng)
            out = {**observation, self.image_key: image}
        else:
            image = out = self._episode_run()(observation, rng=self._rng)  # type: ignore[assignment]  # out: an image here
        self._latency_ms = 1000.0 * (time.perf_counter() - t0)
        self._last_image = image
        return out

    def render(self) -> Any:
        """The env's render; the weathered camera frame of the last step when ``render_weather``
        (default: the env below renders its camera view, ``render_view="camera"``)."""
        if self.render_weather and self.render_mode == "rgb_array" and self._last_image is not None:
            return np.array(self._last_image, copy=True)
        return self.env.render()
