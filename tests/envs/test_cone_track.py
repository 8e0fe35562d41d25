"""ConeTrackEnv: Gymnasium API, determinism, bad input, vector envs, resource cleanup."""

from __future__ import annotations

import gc
import resource

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import env_render_passive_checker

from tests.conftest import SMALL_CAMERA, drive_gt
from weather_gym.agents import AGENTS
from weather_gym.envs import STATE_FIELDS, ConeTrackEnv, EnvConfig


def test_gymnasium_check_env_passes(make_env):
    # skip_render_check: the "human" mode opens the PyBullet GUI, which needs a display;
    # the rgb_array mode is checked below
    check_env(make_env().unwrapped, skip_render_check=True)


def test_stable_baselines3_check_env_passes(make_env):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    sb3_check_env(make_env().unwrapped, warn=False)


def test_rgb_array_render(make_env):
    env = make_env(render_mode="rgb_array")
    env.reset(seed=0)
    env_render_passive_checker(env.unwrapped)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert env.metadata["render_fps"] == 30


def test_observation_and_info_contents(make_env):
    env = make_env()
    obs, info = env.reset(seed=1)
    assert env.observation_space.contains(obs)
    assert obs["state"].shape == (len(STATE_FIELDS),)
    for key in ("gt", "pose", "speed", "lap", "lap_time", "lap_times", "cones_hit", "cross_track_error", "progress"):
        assert key in info
    assert "gt" not in obs and set(obs) == {"image", "depth", "state"}
    assert info["gt"]["boxes"].shape[1] == 4
    obs, reward, terminated, truncated, info = env.step(np.array([0.0, 1.0], np.float32))
    assert isinstance(reward, float) and reward > 0  # moving forward along the track pays
    assert not terminated and not truncated


def test_same_seed_same_actions_give_identical_bytes_for_200_steps(make_env):
    actions = np.random.default_rng(7).uniform([-0.3, 0.2], [0.3, 0.8], size=(200, 2)).astype(np.float32)
    runs = []
    for _ in range(2):
        env = make_env(max_episode_steps=10_000, terminate_off_track=False)
        obs, info = env.reset(seed=42, options={"look": "random"})
        trace = [obs["image"].tobytes(), obs["depth"].tobytes(), obs["state"].tobytes()]
        for a in actions:
            obs, r, term, trunc, info = env.step(a)
            trace += [obs["image"].tobytes(), obs["depth"].tobytes(), obs["state"].tobytes(), repr(r),
                      info["pose"].tobytes(), info["gt"]["boxes"].tobytes()]
        runs.append(trace)
    assert runs[0] == runs[1]


def test_reset_with_the_same_seed_replays_the_episode_on_a_reused_env(make_env):
    env = make_env(track="acceleration", terminate_off_track=False)
    traces = []
    for _ in range(2):
        obs, _ = env.reset(seed=3)
        trace = []
        for _ in range(40):  # drive into the cones on the right: knocked cones are restored at reset
            obs, *_ = env.step(np.array([-0.4, 1.0], np.float32))
            trace.append(obs["image"].tobytes() + obs["state"].tobytes())
        traces.append(trace)
    assert traces[0] == traces[1]


def test_different_seeds_differ_in_odometry_noise(make_env):
    env = make_env()
    s1 = env.reset(seed=1)[0]["state"]
    env.step(np.array([0.0, 1.0], np.float32))
    a = env.step(np.array([0.0, 1.0], np.float32))[0]["state"]
    env.reset(seed=2)
    env.step(np.array([0.0, 1.0], np.float32))
    b = env.step(np.array([0.0, 1.0], np.float32))[0]["state"]
    assert s1.shape == (5,) and not np.array_equal(a, b)


@pytest.mark.parametrize(
    "action,match",
    [([float("nan"), 0.0], "finite"), ([0.0, 1.5], r"\[-1, 1\]"), ([0.0, 0.0, 0.0], "shape"), ([[0.0, 0.0]], "shape")],
)
def test_bad_actions_are_clear_errors(make_env, action, match):
    env = make_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.unwrapped.step(action)


def test_step_before_reset_is_an_error():
    env = ConeTrackEnv(EnvConfig(camera=SMALL_CAMERA))
    try:
        with pytest.raises(RuntimeError, match="reset"):
            env.step(np.zeros(2, np.float32))
    finally:
        env.close()


def test_bad_reset_options_name_the_option(make_env):
    env = make_env()
    with pytest.raises(ValueError, match=r"reset: unknown option\(s\)"):
        env.reset(seed=0, options={"wheather": 1})
    with pytest.raises(ValueError, match="friction"):
        env.reset(seed=0, options={"friction": -1.0})
    with pytest.raises(ValueError, match="look"):
        env.reset(seed=0, options={"look": {"sky_colour": 1}})
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="camera_frame"):
            env.reset(seed=0, options={"camera_frame": bad})


def test_unknown_env_id_and_bad_kwargs():
    import weather_gym  # noqa: F401

    with pytest.raises(gym.error.Error):
        gym.make("WeatherGym/NoSuchTrack-v0")
    with pytest.raises(ValueError, match="unknown key"):
        gym.make("WeatherGym/ConeTrack-v0", camera={"widht": 10})
    with pytest.raises(ValueError, match="width"):
        gym.make("WeatherGym/ConeTrack-v0", camera={"width": 0})
    with pytest.raises(ValueError, match="unknown track"):
        gym.make("WeatherGym/ConeTrack-v0", track="nurburgring", camera=SMALL_CAMERA)


def test_episode_truncates_at_the_time_limit(make_env):
    env = make_env(max_episode_steps=5)
    env.reset(seed=0)
    out = [env.step(np.array([0.0, 0.0], np.float32)) for _ in range(5)]
    assert [o[3] for o in out] == [False] * 4 + [True]
    assert out[-1][4]["is_success"] is False  # truncated before a lap: SB3 reads a failure


def test_is_success_is_in_every_info_and_true_once_the_laps_are_driven(make_env):
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(make_env(track="hairpin", max_episode_steps=2000), info_keywords=("is_success",))
    obs, info = env.reset(seed=0)
    u = env.unwrapped
    agent = AGENTS.get("gt_pure_pursuit")(u.track, u.config.camera)
    agent.reset(seed=0, info=info)
    flags = []
    while True:
        obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
        flags.append(info["is_success"])
        if terminated or truncated:
            break
    assert terminated and info["end_reason"] == "laps"
    assert flags[-1] is True and not any(flags[:-1])
    assert info["episode"]["is_success"] is True  # what Monitor logs (and EvalCallback counts)


def test_leaving_the_track_terminates_and_is_counted(make_env):
    env = make_env(track="acceleration")
    env.reset(seed=0)
    for _ in range(300):
        obs, r, terminated, truncated, info = env.step(np.array([1.0, 0.6], np.float32))
        if terminated:
            break
    assert terminated and info["off_track"] and info["off_track_events"] == 1


def test_cone_hits_are_counted_and_penalised(make_env):
    env = make_env(track="acceleration", terminate_off_track=False)
    cx, cy = env.unwrapped.track.cones_xy[10]
    env.reset(seed=0, options={"start_pose": (cx - 6.0, cy, 0.0), "start_speed": 5.0})
    for _ in range(60):
        obs, r, term, trunc, info = env.step(np.array([0.0, 0.5], np.float32))
        if info["new_cones_hit"]:
            break
    assert info["cones_hit"] >= 1
    assert r < 0  # the hit penalty (-2 per cone) outweighs one step of progress


def test_ground_truth_driver_finishes_a_lap_with_lap_stats(make_env):
    env = make_env(track="hairpin")
    steps, info, _ = drive_gt(env, seed=0)
    assert info["lap"] == 1 and len(info["lap_times"]) == 1
    assert 5.0 < info["lap_times"][0] < 60.0
    assert info["cones_hit"] == 0 and info["off_track_events"] == 0


@pytest.mark.parametrize("vector_cls", [gym.vector.SyncVectorEnv, gym.vector.AsyncVectorEnv])
def test_vector_envs(vector_cls):
    import weather_gym  # noqa: F401

    fns = [lambda: gym.make("WeatherGym/ConeTrack-v0", camera=SMALL_CAMERA) for _ in range(2)]
    venv = vector_cls(fns)
    try:
        obs, info = venv.reset(seed=[0, 0])
        assert obs["image"].shape == (2, SMALL_CAMERA.height, SMALL_CAMERA.width, 3)
        assert np.array_equal(obs["image"][0], obs["image"][1])  # same seed, same bytes in both workers
        for _ in range(3):
            obs, rew, term, trunc, info = venv.step(np.tile(np.array([0.0, 0.5], np.float32), (2, 1)))
        assert rew.shape == (2,) and np.array_equal(obs["state"][0], obs["state"][1])
    finally:
        venv.close()


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


@pytest.mark.slow
def test_creating_and_closing_100_envs_frees_their_clients():
    import pybullet as p

    def cycle():
        env = ConeTrackEnv(EnvConfig(track="hairpin", camera=SMALL_CAMERA))
        env.reset(seed=0)
        env.step(np.zeros(2, np.float32))
        client = env.world.client
        env.close()
        assert not p.isConnected(client)

    for _ in range(10):  # warm-up: allocator pools, EGL driver state
        cycle()
    gc.collect()
    before = _rss_mb()
    for _ in range(90):
        cycle()
    gc.collect()
    grown = _rss_mb() - before
    assert grown < 75, f"memory grew by {grown:.0f} MB over 90 env create/close cycles"


def test_gym_make_max_episode_steps_is_the_step_limit(make_env):
    """gymnasium.make(max_episode_steps=N) is obeyed above the scenario's 3000 too (not silently cut)."""
    import gymnasium as gym

    assert gym.spec("WeatherGym/ConeTrack-v0").max_episode_steps == 3000  # the scenario's [env] value
    env = make_env(max_episode_steps=5000)
    assert env.spec.max_episode_steps == 5000 and not hasattr(env.unwrapped.config, "max_episode_steps")
    env = make_env(max_episode_steps=4)
    env.reset(seed=0)
    flags = [env.step(np.zeros(2, np.float32))[3] for _ in range(4)]
    assert flags == [False, False, False, True]


def test_a_typo_d_reset_option_lists_the_valid_ones_weather_included():
    import weather_gym

    env = weather_gym.make_env(perception="gt_cones", max_episode_steps=5)
    try:
        with pytest.raises(ValueError, match=r"reset: unknown option\(s\) \['weathr'\]; valid options: .*'look'.*'weather'"):
            env.reset(seed=0, options={"weathr": "rain@2"})
    finally:
        env.close()
