"""The pipeline builder: one vocabulary of perception modes, env -> weather -> perception for every caller."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import weather_gym
from tests.conftest import SMALL_CAMERA
from weather_gym.pipeline import PERCEPTION_MODES, make_env, make_vec_env
from weather_gym.wrappers import (
    DetectorWrapper,
    EpisodeStatistics,
    GroundTruthConeWrapper,
    LidarConeWrapper,
    WeatherWrapper,
)


def _chain(env) -> list[type]:
    out = []
    while isinstance(env, gym.Wrapper):
        out.append(type(env))
        env = env.env
    return [*out, type(env)]


def test_one_vocabulary_for_every_caller():
    from weather_gym.cli.lap import perception_choices
    from weather_gym.lab.evaluation.evaluate import PERCEPTIONS

    assert set(PERCEPTION_MODES) == {"camera", "detector", "oracle", "gt_cones", "surrogate", "lidar", "fused"}
    assert PERCEPTIONS == tuple(PERCEPTION_MODES)
    assert perception_choices() == ("auto", *PERCEPTION_MODES)


@pytest.mark.parametrize("perception,keys,wrapper", [
    ("camera", {"image", "depth", "state"}, None),
    ("oracle", {"cones", "mask", "state"}, GroundTruthConeWrapper),
    ("gt_cones", {"cones", "mask", "state"}, GroundTruthConeWrapper),
    ("detector", {"cones", "mask", "state"}, DetectorWrapper),
    ("lidar", {"cones", "mask", "state"}, LidarConeWrapper),
])
def test_each_perception_mode_builds_its_observation(perception, keys, wrapper):
    env = make_env(perception=perception, camera=SMALL_CAMERA, max_episode_steps=50)
    try:
        obs, info = env.reset(seed=0)
        assert set(obs) == keys and env.observation_space.contains(obs)
        chain = _chain(env)
        assert chain[0] is EpisodeStatistics and gym.wrappers.TimeLimit in chain
        assert wrapper is None or wrapper in chain
        obs, *_ = env.step(np.array([0.0, 0.3], np.float32))
        assert env.observation_space.contains(obs)
        assert env.unwrapped.renderer == ("none" if perception == "gt_cones" else env.unwrapped.world.renderer_name)
    finally:
        env.close()


def test_gt_cones_renders_nothing_and_sees_the_cones_ahead():
    env = make_env(perception="gt_cones", max_episode_steps=50)
    try:
        obs, info = env.reset(seed=0)
        u = env.unwrapped
        assert u.renderer == "none" and not u.config.camera_images and u.config.ground_truth == "geometry"
        assert "image" not in u.observation_space.spaces
        assert obs["mask"].sum() >= 4 and info["gt"].count == obs["mask"].sum()
    finally:
        env.close()


def test_gym_make_keywords_and_make_env_build_the_same_stack():
    kw = {"perception": "detector", "weather": "droplets@2", "camera": SMALL_CAMERA}
    a = gym.make("WeatherGym/ConeTrack-v0", **kw)
    b = make_env("WeatherGym/ConeTrack-v0", **kw)
    try:
        assert _chain(b)[1:] == _chain(a)
        assert [WeatherWrapper, DetectorWrapper] == [t for t in _chain(a) if t in (WeatherWrapper, DetectorWrapper)][::-1]
        oa, _ = a.reset(seed=3)
        ob, _ = b.reset(seed=3)
        assert all(np.array_equal(oa[k], ob[k]) for k in oa)
    finally:
        a.close()
        b.close()


def test_bad_settings_are_clear_errors():
    with pytest.raises(ValueError, match="unknown perception 'sonar'; valid: camera, detector, oracle, gt_cones"):
        make_env(perception="sonar")
    with pytest.raises(ValueError, match="needs perception='detector'"):
        make_env(perception="oracle", detector="model.onnx", camera=SMALL_CAMERA)
    with pytest.raises(ValueError, match="acts on camera images.*gt_cones"):
        make_env(perception="gt_cones", weather="droplets@3")
    with pytest.raises(ValueError, match="unknown env id 'WeatherGym/Nope-v0'"):
        make_env("WeatherGym/Nope-v0")
    with pytest.raises(ValueError, match="max_episode_steps must be an integer >= 1"):
        make_env(max_episode_steps=0)
    make_env(perception="gt_cones", weather="clear").close()  # clear weather needs no camera


def test_the_render_free_id_is_registered():
    env = gym.make("WeatherGym/ConeTrackCones-v0")
    try:
        assert env.spec.max_episode_steps == 3000
        obs, _ = env.reset(seed=0)
        assert set(obs) == {"cones", "mask", "state"} and env.unwrapped.renderer == "none"
    finally:
        env.close()


def test_scenario_perception_table_and_the_old_detector_table(tmp_path):
    from weather_gym.envs.scenario import load_scenario

    path = tmp_path / "s.toml"
    path.write_text('id = "WeatherGym/Mine-v0"\n[perception]\nmode = "oracle"\nmiss_prob = 0.5\n[env]\nmax_episode_steps = 7\n')
    sc = load_scenario(path)
    assert sc.perception == {"mode": "oracle", "miss_prob": 0.5} and sc.max_episode_steps == 7
    env = weather_gym.pipeline.make_scenario_env(str(path), camera=SMALL_CAMERA)
    try:
        assert isinstance(env, GroundTruthConeWrapper) and env.noise.miss_prob == 0.5
    finally:
        env.close()
    path.write_text('id = "WeatherGym/Mine-v0"\n[detector]\nenabled = true\n')
    with pytest.raises(ValueError, match=r"\[detector\] table is now \[perception\]"):
        load_scenario(path)


@pytest.mark.parametrize(("table", "message"), [
    ('mode = "detector"\nbogus_kw = 3', r"s.toml \[perception\]: DetectorWrapper \(perception 'detector'\): unknown "
                                         r"argument\(s\) \['bogus_kw'\]"),
    ('mode = "oracle"\nsigma_px = 1', r"s.toml \[perception\]: GroundTruthConeWrapper .* \['sigma_px'\]"),
    ('mode = "oracle"\nmiss_prob = 2.0', r"s.toml \[perception\]: .*miss_prob"),
    ('mode = "nope"', r"s.toml \[perception\] mode: unknown perception 'nope'"),
    ('mode = "camera"\nx = 1', r"s.toml \[perception\]: \['x'\]: perception 'camera' takes no arguments"),
])
def test_a_scenarios_bad_perception_table_names_the_file_before_an_env_is_built(tmp_path, monkeypatch, table,
                                                                                  message):
    from weather_gym.core.errors import FileFormatError

    path = tmp_path / "s.toml"
    path.write_text(f'id = "WeatherGym/Mine-v0"\n[perception]\n{table}\n')
    built = []
    monkeypatch.setattr(weather_gym.pipeline.builder, "ConeTrackEnv", lambda *a, **k: built.append(1))
    with pytest.raises(FileFormatError, match=message):
        weather_gym.pipeline.make_scenario_env(str(path))
    assert built == []


def test_make_vec_env_seeds_each_env_and_stacks_its_info():
    venv = make_vec_env(num_envs=2, vectorization_mode="sync", perception="gt_cones", max_episode_steps=30)
    try:
        obs, info = venv.reset(seed=5)
        assert obs["cones"].shape == (2, 64, 14) and not np.array_equal(obs["state"][0], obs["state"][1])
        assert info["gt"].dtype == object and info["gt"][0].count > 0
        for _ in range(30):
            obs, r, term, trunc, info = venv.step(np.tile([0.0, 0.4], (2, 1)).astype(np.float32))
        assert trunc.all() and info["episode"]["end_reason"].tolist() == ["time_limit"] * 2
    finally:
        venv.close()


def test_the_older_detector_keyword_still_means_the_detector():
    env = gym.make("WeatherGym/ConeTrack-v0", camera=SMALL_CAMERA, detector={"threads": 1, "max_cones": 8})
    off = gym.make("WeatherGym/ConeTrack-v0", camera=SMALL_CAMERA, detector={"enabled": False})
    try:
        assert DetectorWrapper in _chain(env) and env.observation_space["cones"].shape == (8, 14)
        assert DetectorWrapper not in _chain(off) and "image" in off.observation_space.spaces
    finally:
        env.close()
        off.close()
