"""Pure pursuit + speed profile, closed loop on the car's own dynamics (no simulator)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from agent_sim import CarSim, drive, make_track, random_loop

from weather_gym.agents import AGENTS, Agent
from weather_gym.agents.pure_pursuit import (
    PurePursuit,
    PurePursuitConfig,
    path_curvature,
    resample_path,
    speed_profile,
)
from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError
from weather_gym.tracks import TRACKS, load_track


def test_curvature_of_a_circle_is_one_over_radius():
    t = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    ccw = resample_path(np.c_[8 * np.cos(t), 8 * np.sin(t)], 0.25, closed=True)
    k = path_curvature(ccw, closed=True)
    assert np.allclose(k, 1 / 8, rtol=0.02)
    assert np.allclose(path_curvature(ccw[::-1], closed=True), -1 / 8, rtol=0.02)


def test_speed_profile_respects_corner_and_braking_limits():
    step = 0.25
    k = np.zeros(400)
    k[200:240] = 1 / 5.0  # a 5 m radius corner after 50 m of straight
    v = speed_profile(k, step, closed=False, v_max=15, a_lat_max=5, a_accel=3, a_brake=6, v_start=0.0, v_end=0.0)
    assert v[0] == 0.0 and v[-1] == 0.0
    assert np.allclose(v[200:240], 5.0)  # sqrt(a_lat * R)
    assert v.max() <= 15.0 + 1e-9
    dv2 = np.diff(v**2) / step
    assert dv2.max() <= 2 * 3 + 1e-6 and dv2.min() >= -2 * 6 - 1e-6


def test_closed_profile_is_periodic():
    k = np.r_[np.zeros(100), np.full(20, 0.2)]
    v = speed_profile(k, 0.5, closed=True, v_max=12, a_lat_max=5, a_accel=3, a_brake=5)
    # braking before the corner that lies "before" index 0 around the loop
    assert v[-1] == pytest.approx(math.sqrt(25), rel=1e-6)
    assert v[0] < 12 and np.argmax(v) > 0


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match="v_max"):
        PurePursuitConfig(v_max=-1)
    with pytest.raises(ValueError, match="lookahead_max"):
        PurePursuitConfig(lookahead_min=5, lookahead_max=2)
    with pytest.raises(ValueError, match="path"):
        PurePursuit().set_path(np.zeros((4, 3)), closed=False)


def test_steers_towards_the_path_and_stops_at_the_end():
    pp = PurePursuit()
    line = np.c_[np.linspace(0, 40, 81), np.zeros(81)]
    pp.set_path(line, closed=False)
    left_of_line = pp.command(5.0, 1.0, 0.0, 5.0)
    right_of_line = pp.command(5.0, -1.0, 0.0, 5.0)
    assert left_of_line[0] < 0 < right_of_line[0]
    pp.reset()
    at_end = pp.command(40.0, 0.0, 0.0, 4.0)
    assert at_end[1] < 0  # braking to v_end = 0


TRACK_SPECS = [n for n in TRACKS.names() if n != "random"] + ["random:1", "random:2", "random:3"]


@pytest.mark.parametrize("friction", [1.0, 0.6])
@pytest.mark.parametrize("spec", TRACK_SPECS)
def test_gt_pure_pursuit_completes_every_track_without_leaving_it(spec, friction):
    track = load_track(spec)
    agent = AGENTS.get("gt_pure_pursuit")(track, CameraConfig())
    assert isinstance(agent, Agent)
    r = drive(track, agent, friction=friction, max_t=120.0)
    assert r["completed"], f"{spec}: lap not completed in {r['time']:.0f} s"
    # the car (1.2 m wide) keeps at least 0.3 m between its side and the cone lines
    assert r["min_margin"] > 0.3, f"{spec}: margin {r['min_margin']:.2f} m"


def test_gt_pure_pursuit_needs_pose_and_rejects_unknown_options():
    track = load_track("small_track")
    agent = AGENTS.get("gt_pure_pursuit")(track, CameraConfig(), v_max=6.0)
    assert agent.controller.config.v_max == 6.0
    with pytest.raises(ValueError, match="pose"):
        agent.act(None, {})
    with pytest.raises(ValueError, match="unknown option"):
        AGENTS.get("gt_pure_pursuit")(track, CameraConfig(), top_speed=3)


def test_gt_pure_pursuit_is_deterministic():
    track = make_track(random_loop(3))
    runs = []
    for _ in range(2):
        agent = AGENTS.get("gt_pure_pursuit")(track, CameraConfig())
        sim = CarSim(track.start_pose)
        agent.reset(info={"pose": sim.pose, "speed": 0.0})
        acts = []
        for _ in range(60):
            a = agent.act(None, {"pose": sim.pose, "speed": sim.speed})
            sim.step(a)
            acts.append(a)
        runs.append(np.array(acts))
    assert np.array_equal(runs[0], runs[1])


def test_gt_pure_pursuit_slows_only_where_the_track_is_narrow():
    wide, narrow = load_track("peanut"), load_track("random:3,width=2.5")  # 3.8-4.2 m; about 2.5 m
    make = AGENTS.get("gt_pure_pursuit")
    # every shipped layout is wider than 3 m: the same speed profile, to the bit
    assert np.array_equal(make(wide, CameraConfig(), narrow_width=3.0).controller.profile,
                          make(wide, CameraConfig()).controller.profile)
    slow, fast = make(narrow, CameraConfig(), narrow_width=3.0), make(narrow, CameraConfig())
    assert np.all(slow.controller.profile <= fast.controller.profile + 1e-12)
    # in the corners the limit is a_lat_max * (2.5 / 3)**2: speeds about 0.83x
    corner = int(np.argmin(fast.controller.profile))
    assert slow.controller.profile[corner] == pytest.approx(fast.controller.profile[corner] * 2.5 / 3.0, rel=0.06)
    r = drive(narrow, slow, friction=1.0, max_t=120.0)
    assert r["completed"] and r["min_margin"] > 0.3
    for bad in (-1.0, float("nan"), "3"):
        with pytest.raises(InputError, match="narrow_width"):
            make(wide, CameraConfig(), narrow_width=bad)
