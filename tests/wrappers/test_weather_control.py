"""Weather control: set_weather mid-episode through wrappers and vector envs, and WeatherRandomizer."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from weather_gym.weather import parse_weather, to_spec
from weather_gym.wrappers import DetectorWrapper, RandomWeather, WeatherRandomizer, WeatherWrapper

H, W = 48, 64


class Camera(gym.Env):
    """A third-party camera env: a Dict with an image that changes each step."""

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, render_mode=None):
        self.render_mode = render_mode
        self.observation_space = spaces.Dict({"image": spaces.Box(0, 255, (H, W, 3), np.uint8),
                                              "state": spaces.Box(-np.inf, np.inf, (5,), np.float32)})
        self.action_space = spaces.Box(-1, 1, (2,), np.float32)

    def _obs(self):
        img = np.full((H, W, 3), 120 + self.t, np.uint8)
        img[H // 2:, : W // 2] = (200, 120, 30)
        return {"image": img, "state": np.zeros(5, np.float32)}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        return self._obs(), 0.0, False, self.t >= 50, {}

    def render(self):
        return np.zeros((H, W, 3), np.uint8)


def _episode(env, seed, switch_at=None, spec=None, steps=8):
    env.get_wrapper_attr("set_weather")("clear")  # the weather set stays until changed: start clear
    frames = [env.reset(seed=seed)[0]["image"]]
    for t in range(steps):
        if t == switch_at:
            env.get_wrapper_attr("set_weather")(spec)
        frames.append(env.step(np.zeros(2, np.float32))[0]["image"])
    return np.stack(frames)


def test_set_weather_mid_episode_through_wrappers_is_repeatable():
    env = gym.wrappers.TimeLimit(WeatherWrapper(Camera(), weather="clear"), max_episode_steps=100)
    a = _episode(env, seed=3, switch_at=4, spec="rain@3")
    assert env.get_wrapper_attr("weather") == parse_weather("rain@3")
    b = _episode(env, seed=3, switch_at=4, spec="rain@3")
    np.testing.assert_array_equal(a, b)  # same calls, same bytes
    clear = _episode(env, seed=3)
    np.testing.assert_array_equal(a[:5], clear[:5])  # up to the switch: clear
    assert all((a[i] != clear[i]).any() for i in range(5, 9))  # from the next frame: rain
    with pytest.raises(ValueError, match="unknown weather condition 'snow'"):
        env.get_wrapper_attr("set_weather")("snow@2")


def test_assigning_weather_is_set_weather_and_copies_effect_objects():
    shared = parse_weather({"droplets": {"k": 0.5, "persistent": True}})
    envs = [WeatherWrapper(Camera()) for _ in range(2)]
    for e in envs:
        e.reset(seed=0)
        e.weather = shared
    assert envs[0].weather is not envs[1].weather and envs[0].weather == shared
    assert to_spec(envs[0].weather) == to_spec(shared)


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_envs_change_weather_with_call_and_set_attr(mode):
    cls = gym.vector.SyncVectorEnv if mode == "sync" else gym.vector.AsyncVectorEnv
    envs = cls([lambda: WeatherWrapper(Camera(), weather="clear") for _ in range(2)])
    try:
        obs, _ = envs.reset(seed=[1, 2])
        clear = obs["image"].copy()
        specs = envs.call("set_weather", {"dim": 0.5})
        assert [(s[0]["name"], s[0]["k"]) for s in specs] == [("dim", 0.5)] * 2
        obs, *_ = envs.step(np.zeros((2, 2), np.float32))
        assert (obs["image"] < clear + 2).all() and (obs["image"][:, 0, -1] < 100).all()
        envs.set_attr("weather", ["clear", {"dim": 0.9}])
        obs, *_ = envs.step(np.zeros((2, 2), np.float32))
        assert obs["image"][0, 0, -1, 0] == 122 and obs["image"][1, 0, -1, 0] < 20
        specs = envs.call("set_weather", "fog@2")
        assert [s[0]["name"] for s in specs] == ["fog", "fog"]
    finally:
        envs.close()


def test_random_weather_draws_everything_from_the_generator():
    rw = RandomWeather(presets=("rain", "dim"), severities=(1, 4), effects={"fog": (0.2, 0.4), "noise": 0.3}, p=0.5)
    draws = [rw.sample(np.random.default_rng(s)) for s in range(200)]
    again = [rw.sample(np.random.default_rng(s)) for s in range(200)]
    assert draws == again
    labels = [d[1] for d in draws]
    assert {lb.split(" + ")[0] for lb in labels} == {"rain@1", "rain@4", "low_light@1", "low_light@4"}
    fog_ks = [t["k"] for spec, _ in draws for t in spec if t["name"] == "fog"]
    assert 60 < len(fog_ks) < 140 and all(0.2 <= k <= 0.4 for k in fog_ks)  # p = 0.5 of 200
    assert all(parse_weather(spec) is not None for spec, _ in draws)
    clear = RandomWeather(presets=("rain",), p_clear=1.0).sample(np.random.default_rng(0))
    assert clear == ([], "clear")
    ramp, _ = RandomWeather(presets=(), effects={"dim": 0.8}, p=1.0, schedule="ramp", every=10).sample(
        np.random.default_rng(0))
    assert ramp == [{"name": "ramp", "effect": "dim", "k_start": 0.0, "k_end": 0.8, "steps": 10}]


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"presets": ("snow",)}, "unknown weather condition 'snow'"),
    ({"severities": (5,)}, "invalid severity 5"),
    ({"effects": {"fog": (0.6, 0.2)}}, "0 <= low <= high <= 1"),
    ({"effects": {"hail": 0.2}}, "unknown weather effect 'hail'"),
    ({"effects": {"fog": {"visibility": 3}}}, "needs 'k'"),
    ({"p": 1.5}, r"RandomWeather.p must be a finite number in \[0, 1\], got 1.5"),
    ({"schedule": "hourly"}, "schedule must be one of episode, step, ramp"),
    ({"every": 0}, "every must be an integer >= 1"),
    ({"presets": (), "effects": {}}, "give presets and/or effects"),
])
def test_random_weather_refuses_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        RandomWeather(**kwargs)
    with pytest.raises(ValueError, match="unknown option"):
        WeatherRandomizer(Camera(), presets=("rain",), severity=2)


def _run(env, seed, steps=12):
    obs, info = env.reset(seed=seed)
    draws, frames = [info["weather_draw"]], [obs["image"]]
    for _ in range(steps):
        obs, _, _, _, info = env.step(np.zeros(2, np.float32))
        draws.append(info["weather_draw"])
        frames.append(obs["image"])
    return draws, np.stack(frames)


def test_randomizer_per_episode_and_per_step_from_the_reset_seed():
    env = WeatherRandomizer(Camera(), presets=("rain", "fog", "low_light"), severities=(2, 3, 4))  # adds the wrapper
    assert isinstance(env.env, WeatherWrapper)
    per_seed = {s: _run(env, s) for s in range(6)}
    for s in range(6):
        draws, frames = _run(env, s)
        assert draws == per_seed[s][0] and len(set(draws)) == 1  # one draw per episode
        np.testing.assert_array_equal(frames, per_seed[s][1])
    assert len({d[0][0] for d in per_seed.values()}) > 1  # seeds give different weather

    stepped = WeatherRandomizer(WeatherWrapper(Camera()), presets=(), effects={"dim": (0.1, 0.9)}, p=1.0,
                                schedule="step", every=4)
    draws, frames = _run(stepped, 7)
    assert draws[:5] == [draws[0]] * 5 and draws[5] != draws[4] and draws[9] != draws[8]
    assert _run(stepped, 7)[0] == draws
    np.testing.assert_array_equal(_run(stepped, 7)[1], frames)


def test_an_explicit_weather_option_wins_and_a_detector_in_between_is_fine():
    env = WeatherRandomizer(WeatherWrapper(Camera()), presets=("rain",), severities=(4,))
    obs, info = env.reset(seed=0, options={"weather": "clear"})
    assert info["weather_draw"] == "explicit" and info["weather"] == []
    with pytest.raises(ValueError, match="needs a WeatherWrapper below it"):
        WeatherRandomizer(DetectorWrapper(Camera()), presets=("rain",))


def test_randomizer_on_a_detector_env_needs_no_weather_given():
    import weather_gym
    from weather_gym.wrappers import EpisodeStatistics

    env = WeatherRandomizer(weather_gym.make_env(camera={"width": 160, "height": 90}, perception="detector",
                                                 max_episode_steps=3), presets=("rain",), severities=(3,))
    try:
        assert isinstance(env.env, EpisodeStatistics)  # the make_env stack kept: its WeatherWrapper is below
        obs, info = env.reset(seed=0)
        assert info["weather_draw"] == "rain@3" and info["weather"][0]["name"] == "rain"
        assert sorted(obs) == ["cones", "mask", "state"]
    finally:
        env.close()
