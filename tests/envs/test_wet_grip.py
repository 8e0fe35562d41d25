"""The water film reaches the tyres: less grip, less turn, slower laps."""

import numpy as np
import pytest

from weather_gym.core.errors import InputError, LimitError


def _turn(env, film: float) -> float:
    """Change of the direction of travel after 1 s of full steering from 12 m/s (the tyres' lateral force)."""
    env.reset(seed=0, options={"start_speed": 12.0, "water_film_mm": film})
    car = env.unwrapped.world.car
    c0 = np.arctan2(*car.velocity_world[::-1])
    for _ in range(30):
        env.step(np.array([1.0, 0.0], np.float32))
    c1 = np.arctan2(*car.velocity_world[::-1])
    return abs(float(np.unwrap([c0, c1])[1] - c0))


def test_turn_falls_monotonically_with_the_water_film(make_env):
    env = make_env(camera_images=False, ground_truth="geometry", track="skidpad")
    turns = [_turn(env, film) for film in (0.0, 0.2, 0.5, 1.0, 2.0)]
    assert all(a > b for a, b in zip(turns, turns[1:])), turns


def test_friction_now_and_mid_episode_change(make_env):
    env = make_env(camera_images=False, ground_truth="geometry")
    env.reset(seed=0, options={"start_speed": 10.0, "water_film_mm": 0.2, "friction": 1.2})
    u = env.unwrapped
    assert u.water_film_mm == 0.2 and u.friction_now == pytest.approx(1.2 * 0.65 / 0.85)
    u.set_water_film(0.0)
    assert u.friction_now == 1.2
    with pytest.raises(LimitError, match="3 mm"):
        u.set_water_film(3.0)
    with pytest.raises(InputError, match="water_film_mm"):
        u.set_water_film("wet")
    env.reset(seed=0)
    assert u.water_film_mm == 0.0  # a reset without the option is dry


def test_a_lap_is_slower_in_puddles(make_env):
    from tests.conftest import drive_gt

    env = make_env(camera_images=False, ground_truth="geometry", track="small_track")
    times = []
    for film in (0.0, 2.0):
        steps, info, _ = drive_gt(env, seed=0, max_steps=3000, options={"water_film_mm": film})
        times.append((steps, info.get("end_reason")))
    assert times[1][0] > times[0][0], times  # 632 against 630 steps (gt_pure_pursuit drives well inside the grip)
