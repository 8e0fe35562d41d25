"""The cone shield keeps a driver's steering off the cones in its list, leaves clear actions alone,
and on a tight narrow track turns the shipped driver's crash into a clean lap."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.agents.cone_shield import ConeShield, ConeShieldConfig
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import FIELD


def _obs(*cones: tuple[float, float], speed: float = 5.0, yaw_rate: float = 0.0, n: int = 8) -> dict:
    rows = np.zeros((n, 14), np.float32)
    mask = np.zeros(n, np.int8)
    for i, (x, y) in enumerate(cones):
        rows[i, FIELD["x_body"]], rows[i, FIELD["y_body"]] = x, y
        mask[i] = 1
    return {"cones": rows, "mask": mask, "state": np.array([speed, yaw_rate, 0, 0, 0], np.float32)}


def test_actions_that_keep_off_the_cones_pass_unchanged():
    shield = ConeShield()
    action = np.array([0.1, 0.7], np.float32)
    for obs in (_obs(), _obs((6.0, 1.75), (6.0, -1.75), (10.0, 1.75), (10.0, -1.75)), _obs((3.0, 0.0), n=4) | {
            "mask": np.zeros(4, np.int8)}):
        np.testing.assert_array_equal(shield(obs, action), action)
    assert shield.interventions == 0


def test_a_cone_ahead_is_steered_round_within_max_change_keeping_the_pedal():
    shield = ConeShield()
    steer, pedal = shield(_obs((6.0, 0.3), speed=8.0), np.array([0.0, 0.5], np.float32))
    assert -0.3 - 1e-6 <= steer < 0 and pedal == 0.5  # right of a cone left of the nose
    steer_m, _ = ConeShield()(_obs((6.0, -0.3), speed=8.0), np.array([0.0, 0.5], np.float32))
    assert steer_m == pytest.approx(-steer)  # the mirror image, mirrored
    assert shield.interventions == 1
    shield.reset()
    assert shield.interventions == 0


def test_a_gap_narrower_than_the_car_brakes():
    shield = ConeShield()
    steer, pedal = shield(_obs((3.5, 0.5), (3.5, -0.5)), np.array([0.0, 0.8], np.float32))
    assert pedal == ConeShieldConfig().brake and abs(steer) <= ConeShieldConfig().max_change


def test_a_crawling_car_keeps_its_pedal_where_nothing_clears():
    """Stopped against cones it cannot steer clear of, braking would hold the car there for good."""
    stuck = _obs((2.3, 0.2), (2.3, -0.2), speed=0.3)
    steer, pedal = ConeShield()(stuck, np.array([0.1, 0.4], np.float32))
    assert pedal == pytest.approx(0.4) and abs(steer - 0.1) <= ConeShieldConfig().max_change + 1e-6
    _, pedal = ConeShield()(_obs((3.3, 0.2), (3.3, -0.2), speed=3.0), np.array([0.1, 0.4], np.float32))
    assert pedal == ConeShieldConfig().brake


def test_a_cone_already_close_may_stay_close_but_not_come_closer():
    """Beside the car inside the margin: driving straight on passes, steering into it does not."""
    shield = ConeShield()
    beside = _obs((1.0, -0.75))  # 0.15 - 0.114 = 0.036 m from the body's right side
    straight = np.array([0.0, 0.3], np.float32)
    np.testing.assert_array_equal(shield(beside, straight), straight)
    steer, pedal = shield(beside, np.array([-0.5, 0.3], np.float32))
    assert steer > -0.5 and pedal == ConeShieldConfig().brake  # every steering within reach closes in: brake


def test_the_config_is_checked():
    with pytest.raises(InputError, match="candidates must be odd"):
        ConeShieldConfig(candidates=40)
    with pytest.raises(InputError, match="brake"):
        ConeShieldConfig(brake=0.5)
    with pytest.raises(InputError, match="unknown .*horizn"):
        ConeShieldConfig.from_dict({"horizn": 1.0})
    with pytest.raises(InputError, match="cone_shield must be a table"):
        ConeShieldConfig.from_dict("yes")  # type: ignore[arg-type]
    assert ConeShieldConfig.from_dict(ConeShieldConfig(margin=0.2).to_dict()) == ConeShieldConfig(margin=0.2)


def test_ppo_cones_drives_with_the_shield_its_json_records():
    pytest.importorskip("stable_baselines3")
    import json

    from weather_gym.agents import AGENTS
    from weather_gym.core.paths import PPO_CONES_MODEL

    meta = json.loads(PPO_CONES_MODEL.with_suffix(".json").read_text())
    assert AGENTS.get("ppo_cones")(None, None).shield.config == ConeShieldConfig.from_dict(meta["cone_shield"])
    assert AGENTS.get("ppo_cones")(None, None, cone_shield=False).shield is None


@pytest.mark.slow
def test_on_a_tight_narrow_oval_the_shield_turns_a_crash_into_a_clean_lap(tmp_path):
    """A 2.4 m wide oval with 6 m turns, narrower and tighter than any training track: without the
    shield the shipped driver cuts the first turn, hits cones and leaves the track."""
    pytest.importorskip("stable_baselines3")
    from weather_gym.agents import AGENTS
    from weather_gym.pipeline import make_env
    from weather_gym.pipeline.episode import run_episode
    from weather_gym.tracks import oval

    path = oval(straight=20.0, radius=6.0, width=2.4).to_csv(tmp_path / "tight_oval.csv")
    results = {}
    for shield in (False, True):
        env = make_env(perception="gt_cones", track=str(path), max_episode_steps=900)
        agent = AGENTS.get("ppo_cones")(env.unwrapped.track, env.unwrapped.config.camera, cone_shield=shield)
        results[shield] = run_episode(env, agent, seed=0)
        env.close()
    assert not results[False].completed and results[False].cones_hit > 0, results[False]
    assert results[True].completed and results[True].cones_hit == 0 and results[True].off_track_events == 0, results[True]
