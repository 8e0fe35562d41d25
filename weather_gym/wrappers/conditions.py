"""``ConditionsWrapper``: one physical weather state for the camera, the LiDAR and the tyres.

It stands on top of a stack (any perception mode) and hands the state
(:class:`~weather_gym.conditions.WeatherState`, a spec like ``"rain:8mm/h+fog:60m"``) to each part
that is there: the camera's effects to the ``WeatherWrapper`` (:func:`~weather_gym.conditions.camera_tables`),
the LiDAR's to the ``LidarConeWrapper`` / ``FusionWrapper`` (:func:`~weather_gym.conditions.lidar_weather`)
and the water film to the env's tyres (``reset`` option ``water_film_mm``). A stack without a camera gets
no camera weather, one without a LiDAR no LiDAR weather; the tyres always get the film.

``reset(options={"conditions": SPEC})`` sets the state for an episode; ``set_conditions(SPEC)`` changes
it from the next step (the lens keeps the wetness it has reached); ``ramp_to(SPEC, seconds)`` moves it
linearly there (extinction, rates, film and the logarithm of the light), updated once a simulated
second. ``info["conditions"]`` is the state's spec, ``info["friction"]`` the tyres' friction of the step.

Example:
    >>> from weather_gym.pipeline import make_env
    >>> env = make_env("WeatherGym/ConeTrack-v0", perception="lidar", conditions="rain:8mm/h+fog:60m",
    ...                max_episode_steps=5)
    >>> obs, info = env.reset(seed=0)
    >>> info["conditions"], info["lidar_weather"].split("+")[1][:4], round(info["friction"], 3)
    ('fog:60m+rain:8mm/h', 'rain', 0.647)
    >>> env.close()
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import gymnasium as gym

from weather_gym.conditions import WeatherState, camera_tables, lidar_weather, parse_state
from weather_gym.core.errors import InputError
from weather_gym.wrappers._chain import find_wrapper
from weather_gym.wrappers.lidar import LidarConeWrapper
from weather_gym.wrappers.weather import WeatherWrapper

__all__ = ["ConditionsWrapper", "interpolate"]


def interpolate(a: WeatherState, b: WeatherState, t: float) -> WeatherState:
    """The state ``t`` (0-1) of the way from ``a`` to ``b``: extinction, rates, film and lens linear, the
    light linear in its logarithm."""
    t = min(max(float(t), 0.0), 1.0)
    beta = (1 - t) * a.beta + t * b.beta
    mor = math.inf if beta <= 0 else math.log(20.0) / beta
    lo, hi = sorted((a.illuminance_lux, b.illuminance_lux))  # exp(log) may leave the pair by a rounding
    lux = min(max(math.exp((1 - t) * math.log(a.illuminance_lux) + t * math.log(b.illuminance_lux)), lo), hi)
    film = (1 - t) * a.film_mm() + t * b.film_mm()
    return WeatherState(mor_m=mor, rain_mm_h=(1 - t) * a.rain_mm_h + t * b.rain_mm_h,
                        snow_mm_h=(1 - t) * a.snow_mm_h + t * b.snow_mm_h, illuminance_lux=lux,
                        water_film_mm=film if (a.water_film_mm is not None or b.water_film_mm is not None or film)
                        else None,
                        lens_wetness=(1 - t) * a.lens_wetness + t * b.lens_wetness, lens_wet_up_s=b.lens_wet_up_s)


class ConditionsWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """One weather state for every sensor and the tyres (see the module doc).

    Args:
        env: a weather-gym stack (``make_env(..., conditions=...)`` builds it).
        conditions: a state spec (``"rain:8mm/h+fog:60m"``), a ``WeatherState`` or None (clear).
    """

    def __init__(self, env: gym.Env, conditions: Any = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, conditions=conditions)
        gym.Wrapper.__init__(self, env)
        self.state = parse_state(conditions)
        self._default = self.state
        self._camera: WeatherWrapper | None = find_wrapper(env, WeatherWrapper)
        self._lidar: LidarConeWrapper | None = find_wrapper(env, LidarConeWrapper)
        self._hz = float(getattr(getattr(getattr(env.unwrapped, "config", None), "sim", None), "control_hz", 30.0))
        self._has_images = isinstance(env.observation_space, gym.spaces.Dict) and "image" in env.observation_space.spaces
        self._lens_step = 0
        self._ramp: tuple[WeatherState, WeatherState, int, int] | None = None
        self._step = 0
        self._check(self.state)

    def _check(self, state: WeatherState) -> None:
        tables = camera_tables(state, self._hz)
        base = self.env.unwrapped
        renders = bool(getattr(getattr(base, "config", None), "camera_images", False))
        if tables and renders and self._camera is None:
            raise InputError(f"conditions {state.spec()!r} reach the camera, and this stack has no WeatherWrapper "
                             "to apply them (build it with make_env(..., conditions=...))")

    def _options(self, state: WeatherState) -> dict[str, Any]:
        out: dict[str, Any] = {"water_film_mm": state.film_mm()}
        if self._camera is not None:
            out["weather"] = camera_tables(state, self._hz) or "clear"
        if self._lidar is not None:
            out["lidar_weather"] = lidar_weather(state)
        return out

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        options = dict(options or {})
        self.state = parse_state(options.pop("conditions")) if "conditions" in options else self._default
        self._check(self.state)
        clash = sorted(set(options) & {"weather", "lidar_weather", "water_film_mm"})
        if clash:
            raise InputError(f"reset options {clash} clash with the conditions {self.state.spec()!r}: give the "
                             "weather as conditions only")
        options.update(self._options(self.state))
        self._lens_step, self._step, self._ramp = 0, 0, None
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, self._info(info)

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict]:
        self._step += 1
        self._lens_step += 1
        if self._ramp is not None:
            a, b, start, steps = self._ramp
            done = self._step - start
            if done % max(1, int(round(self._hz))) == 0 or done >= steps:
                self._apply(interpolate(a, b, done / steps))
                if done >= steps:
                    self._ramp = None
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, self._info(info)

    def _info(self, info: dict) -> dict:
        info = dict(info)
        info["conditions"] = self.state.spec()
        info["friction"] = float(getattr(self.env.unwrapped, "friction_now", math.nan))
        return info

    def lens_now(self) -> float:
        """The lens wetness reached now (its ramp towards the rain's equilibrium)."""
        s = self.state
        steps = max(1, int(round(s.lens_wet_up_s * self._hz)))
        return s.lens_wetness + (s.lens_equilibrium() - s.lens_wetness) * min(self._lens_step / steps, 1.0)

    def _apply(self, state: WeatherState) -> None:
        state = replace(state, lens_wetness=round(min(self.lens_now(), 1.0), 9))
        self._check(state)
        self.state = state
        self._lens_step = 0
        opts = self._options(state)
        if self._camera is not None:
            self._camera.set_weather(opts["weather"])
        if self._lidar is not None:
            self._lidar.weather = opts["lidar_weather"]
        self.env.unwrapped.set_water_film(opts["water_film_mm"])  # type: ignore[attr-defined]  # a ConeTrackEnv

    def set_conditions(self, spec: Any) -> WeatherState:
        """Change the weather state from the next step on (the lens keeps its wetness); returns the state."""
        self._ramp = None
        self._apply(parse_state(spec))
        return self.state

    def ramp_to(self, spec: Any, seconds: float) -> None:
        """Move the state linearly to ``spec`` over ``seconds`` of simulated time (updated once a second)."""
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not seconds > 0:
            raise InputError(f"ramp_to: seconds must be a number > 0, got {seconds!r}")
        target = parse_state(spec)
        self._ramp = (self.state, target, self._step, max(1, int(round(seconds * self._hz))))
