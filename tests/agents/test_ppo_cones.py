"""The shipped PPO driver loads from the package and acts on a cone list (any source of cones)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from weather_gym.paths import PPO_CONES_MODEL


def test_the_shipped_policy_is_small_and_documented():
    assert PPO_CONES_MODEL.is_file() and PPO_CONES_MODEL.stat().st_size < 5 * 2**20
    meta = json.loads(PPO_CONES_MODEL.with_suffix(".json").read_text())
    assert meta["perception"] == "gt_cones" and meta["track"] not in meta["train_tracks"]  # held out


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
