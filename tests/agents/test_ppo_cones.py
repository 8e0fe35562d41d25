"""The shipped learned driver loads from the package, acts on a cone list (any source of cones) and laps a
track it never saw from the start line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from weather_gym.core.paths import PPO_CONES_MODEL


def test_the_shipped_policy_is_small_and_documented():
    assert PPO_CONES_MODEL.is_file() and PPO_CONES_MODEL.stat().st_size < 5 * 2**20
    meta = json.loads(PPO_CONES_MODEL.with_suffix(".json").read_text())
    assert meta["perception"] == "surrogate" and meta["track"] not in meta["train_tracks"]  # held out
    assert meta["pretrain"]["expert"] == "gt_pure_pursuit" and meta["command"].startswith("weather-gym train")
    assert "--cone-memory" in meta["command"] and isinstance(meta["cone_memory"], dict)


def test_ppo_cones_reads_the_cone_list_through_the_memory_it_was_trained_with():
    pytest.importorskip("stable_baselines3")
    from weather_gym.agents import AGENTS
    from weather_gym.agents.cone_memory import ConeMemoryConfig
    from weather_gym.camera.config import CameraConfig

    meta = json.loads(PPO_CONES_MODEL.with_suffix(".json").read_text())
    agent = AGENTS.get("ppo_cones")(None, CameraConfig())
    expected = ConeMemoryConfig.from_dict(meta["cone_memory"])
    assert agent.memory.config == expected and agent.memory.mount_x == CameraConfig().mount_x
    assert expected.detection_range == 30.0  # it drives on lists cut where the surrogate's thin out


def test_ppo_cones_drives_from_a_cone_list():
    pytest.importorskip("stable_baselines3")
    from weather_gym.agents import AGENTS
    from weather_gym.perception.cones import FIELD, cone_list_space

    agent = AGENTS.get("ppo_cones")(None, None)
    agent.reset(seed=0)
    space = cone_list_space()
    cones = np.zeros(space["cones"].shape, np.float32)
    mask = np.zeros(space["mask"].shape, np.int8)
    for i, (x, y, c) in enumerate([(4, 1.6, "blue"), (4, -1.6, "yellow"), (8, 1.6, "blue"), (8, -1.6, "yellow")]):
        cones[i, FIELD[f"is_{c}"]] = 1
        cones[i, FIELD["x_body"]], cones[i, FIELD["y_body"]] = x, y
        mask[i] = 1
    action = agent.act({"cones": cones, "mask": mask, "state": np.zeros(5, np.float32)})
    assert action.dtype == np.float32 and action.shape == (2,) and np.all(np.abs(action) <= 1)
    again = agent.act({"cones": cones, "mask": mask, "state": np.zeros(5, np.float32)})
    np.testing.assert_array_equal(action, again)  # deterministic: the same cones, the same action


@pytest.mark.slow
def test_ppo_cones_leaves_the_start_line_and_laps_a_held_out_track():
    """The failure it replaces: a policy that stood at the start line until the time limit."""
    pytest.importorskip("stable_baselines3")
    from weather_gym.agents import AGENTS
    from weather_gym.pipeline import make_env
    from weather_gym.pipeline.episode import run_episode

    env = make_env(perception="surrogate", weather="droplets@2", track="small_track", max_episode_steps=1200)
    meta = json.loads(PPO_CONES_MODEL.with_suffix(".json").read_text())
    assert "small_track" not in meta["train_tracks"]
    agent = AGENTS.get("ppo_cones")(env.unwrapped.track, env.unwrapped.config.camera)
    result = run_episode(env, agent, seed=0)
    env.close()
    assert result.completed, result
    assert result.cones_hit <= 2 and result.off_track_events == 0, result


@pytest.mark.slow
@pytest.mark.parametrize(("name", "weather"), [("hairpin", "droplets@3"), ("peanut", "droplets@1"),
                                               ("peanut", "droplets@3"), ("peanut", "low_light@1")])
def test_ppo_cones_laps_the_mirror_image_of_a_training_track(name, weather):
    """Tight turns the other way: a driver trained on eight tracks one way round left the mirrored
    hairpin at a third of the lap and hit 6 cones on the mirrored peanut; one that read only the
    frame's cones (no cone memory) hit up to 3 cones there at droplets S3 and left it at low light S1,
    where the cone list is thinnest (CHANGELOG.md)."""
    pytest.importorskip("stable_baselines3")
    from weather_gym.agents import AGENTS
    from weather_gym.pipeline import make_env
    from weather_gym.pipeline.episode import run_episode

    env = make_env(perception="surrogate", weather=weather, track=f"mirror:{name}", max_episode_steps=1200)
    agent = AGENTS.get("ppo_cones")(env.unwrapped.track, env.unwrapped.config.camera)
    result = run_episode(env, agent, seed=0)
    env.close()
    assert result.completed, result
    assert result.cones_hit <= 1 and result.off_track_events == 0, result


@pytest.mark.slow
def test_ppo_cones_laps_on_perfect_cones_too():
    """Geometric ground truth lists every cone in view, to 70 m; the driver, cloned on the surrogate's
    lists (which thin out near 30 m), hit 4-6 cones a lap here when it read them all (CHANGELOG.md)."""
    pytest.importorskip("stable_baselines3")
    from weather_gym.agents import AGENTS
    from weather_gym.pipeline import make_env
    from weather_gym.pipeline.episode import run_episode

    env = make_env(perception="gt_cones", track="random:100", max_episode_steps=1200)
    agent = AGENTS.get("ppo_cones")(env.unwrapped.track, env.unwrapped.config.camera)
    result = run_episode(env, agent, seed=0)
    env.close()
    assert result.completed and result.cones_hit == 0 and result.off_track_events == 0, result
