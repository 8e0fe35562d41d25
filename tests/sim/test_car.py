"""The car's dynamic bicycle model: acceleration, braking, friction-limited cornering."""

from __future__ import annotations

import math

import pytest

from weather_gym.sim.car import Car
from weather_gym.sim.config import CarConfig

DT = 1 / 240


def run(car: Car, seconds: float, steer: float, pedal: float, friction: float | None = None) -> None:
    for _ in range(int(seconds / DT)):
        car.step(DT, steer, pedal, friction)


def test_full_throttle_accelerates_and_brakes_stop_without_reversing():
    car = Car()
    car.reset(0, 0, 0)
    run(car, 1.0, 0.0, 1.0)
    assert 4.5 < car.speed < 6.5  # max_accel 6 m/s^2 minus resistance
    run(car, 3.0, 0.0, -1.0)
    assert car.speed == 0.0
    x_stopped = car.pose[0]
    run(car, 1.0, 0.0, -1.0)
    assert car.pose[0] == pytest.approx(x_stopped)  # brakes never reverse the car


def peak_acceleration(car: Car, seconds: float, steer: float, pedal: float, friction: float | None = None) -> float:
    peak, v_prev = 0.0, car.velocity_world
    for _ in range(int(seconds / DT)):
        car.step(DT, steer, pedal, friction)
        v = car.velocity_world
        peak = max(peak, math.hypot(v[0] - v_prev[0], v[1] - v_prev[1]) / DT)
        v_prev = v
    return peak


@pytest.mark.parametrize("mu", [1.0, 0.6])
def test_acceleration_is_limited_by_friction(mu):
    """Full lock at speed: the car's acceleration (from its world velocity) stays inside the
    friction circle mu * g (plus aerodynamic drag), and uses most of it."""
    car = Car(CarConfig(friction=mu))
    car.reset(0, 0, 0, speed=15.0)
    peak = peak_acceleration(car, 2.0, 1.0, 0.0)
    drag = CarConfig().drag * 15.0**2 / CarConfig().mass
    assert peak <= mu * 9.81 * 1.02 + drag
    assert peak >= mu * 9.81 * 0.6


def test_wet_road_grip_is_a_per_step_parameter():
    """The same manoeuvre on a wet road (friction passed per step) reaches less acceleration."""
    peaks = {}
    for mu in (1.0, 0.5):
        car = Car()
        car.reset(0, 0, 0, speed=12.0)
        peaks[mu] = peak_acceleration(car, 3.0, 0.6, 0.15, friction=mu)
    drag = CarConfig().drag * 12.0**2 / CarConfig().mass
    assert peaks[0.5] <= 0.5 * 9.81 * 1.02 + drag
    assert peaks[1.0] > peaks[0.5] * 1.5


def test_low_speed_turn_follows_kinematic_geometry():
    cfg = CarConfig()
    car = Car(cfg)
    car.reset(0, 0, 0, speed=0.5)
    steer = 0.5
    run(car, 0.5, steer, 0.0)
    delta = car.state.steer
    expected = car.speed * math.tan(delta) / cfg.wheelbase
    assert car.state.yaw_rate == pytest.approx(expected, rel=0.05)


def test_pose_is_the_rear_axle():
    car = Car()
    car.reset(3.0, -2.0, 0.7)
    x, y, yaw = car.pose
    assert (x, y, yaw) == pytest.approx((3.0, -2.0, 0.7))


@pytest.mark.parametrize("field,value", [("mass", 0), ("wheelbase", float("nan")), ("max_steer", 2.0), ("cg_to_rear", 5.0)])
def test_bad_car_config_is_a_clear_error(field, value):
    with pytest.raises(ValueError, match=field):
        CarConfig(**{field: value})


def _manoeuvre(car: Car) -> None:
    """Weave at full throttle, brake, roll on; friction changing every third step (as a wet patch would)."""
    for t in range(720):
        steer = 1.0 if (t // 90) % 2 == 0 else -0.7
        pedal = 1.0 if t < 400 else (-0.8 if t < 500 else 0.3)
        car.step(DT, steer, pedal, None if t % 3 else 0.6)


def test_the_model_gives_the_same_floats_as_ever():
    """Same seed, same bytes across versions: the compiled model reproduces, to the last bit, the
    state that the model's pure-Python form reached after this manoeuvre (pinned when it was compiled)."""
    car = Car(CarConfig(friction=0.9))
    car.reset(1.0, -2.0, 0.3, speed=4.0)
    _manoeuvre(car)
    s = car.state
    assert (s.x, s.y, s.yaw, s.vx, s.vy, s.yaw_rate, s.steer) == (
        0.7588201261776661, 5.792060014403517, 2.490019735472817, 3.359578925223307, -0.5017221715794608,
        -0.6828919027456029, -0.315)


def test_n_steps_in_one_call_equal_n_calls():
    one, many = Car(), Car()
    for car in (one, many):
        car.reset(0.0, 0.0, 0.2, speed=6.0)
    for _ in range(200):
        for _ in range(8):
            one.step(DT, 0.4, 0.6)
        many.step(DT, 0.4, 0.6, n=8)
    assert one.state == many.state
