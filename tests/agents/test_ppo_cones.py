"""The shipped learned driver loads from the package, acts on a cone list (any source of cones) and laps a
track it never saw from the start line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from weather_gym.paths import PPO_CONES_MODEL


def test_the_shipped_policy_is_small_and_documented():
    assert PPO_CONES_MODEL.is_file() and PPO_CONES_MODEL.stat().st_size < 5 * 2**20
    meta = json.loads(PPO_CONES_MODEL.with_suffix(".json").read_text())
    assert meta["perception"] == "surrogate" and meta["track"] not in meta["train_tracks"]  # held out
    assert meta["pretrain"]["expert"] == "gt_pure_pursuit" and meta["command"].startswith("weather-gym train")


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
    from weather_gym.agents import AGENTS, run_episode
    from weather_gym.pipeline import make_env

    env = make_env(perception="surrogate", weather="droplets@2", track="small_track", max_episode_steps=1200)
    meta = json.loads(PPO_CONES_MODEL.with_suffix(".json").read_text())
    assert "small_track" not in meta["train_tracks"]
    agent = AGENTS.get("ppo_cones")(env.unwrapped.track, env.unwrapped.config.camera)
    result = run_episode(env, agent, seed=0)
    env.close()
    assert result.completed, result
    assert result.cones_hit <= 2 and result.off_track_events == 0, result


def _mirrored_csv(name: str, path):
    """``name``'s cones reflected across the x axis (blue and yellow swapped, so blue stays on the
    driver's left): every left turn a right turn. A layout the policy never drove."""
    from weather_gym.tracks import CONE_CLASSES, load_track

    t = load_track(name)
    swap = {"blue": "yellow", "yellow": "blue"}
    x, y, yaw = t.start_pose
    rows = ["tag,x,y,direction", f"car_start,{x!r},{-y!r},{-yaw!r}"]
    rows += [f"{swap.get(CONE_CLASSES[c], CONE_CLASSES[c])},{cx!r},{-cy!r},0"
             for (cx, cy), c in zip(t.cones_xy.tolist(), t.cone_classes.tolist(), strict=True)]
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.slow
@pytest.mark.parametrize("name", ["hairpin", "peanut"])
def test_ppo_cones_laps_the_mirror_image_of_a_training_track(name, tmp_path):
    """Tight turns the other way: the previous driver (trained on eight tracks one way round) left the
    mirrored hairpin at a third of the lap and hit 6 cones on the mirrored peanut."""
    pytest.importorskip("stable_baselines3")
    from weather_gym.agents import AGENTS, run_episode
    from weather_gym.pipeline import make_env

    track = str(_mirrored_csv(name, tmp_path / f"{name}_mirrored.csv"))
    env = make_env(perception="surrogate", weather="droplets@3", track=track, max_episode_steps=1200)
    agent = AGENTS.get("ppo_cones")(env.unwrapped.track, env.unwrapped.config.camera)
    result = run_episode(env, agent, seed=0)
    env.close()
    assert result.completed, result
    assert result.cones_hit <= 1 and result.off_track_events == 0, result
