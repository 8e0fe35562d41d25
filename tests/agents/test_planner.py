"""Centre-line planner on mapped cones: straight, one-sided, hairpins and every shipped track."""

from __future__ import annotations

import numpy as np
import pytest
from agent_sim import distance_to_polyline

from weather_gym.agents.planner import CenterlinePlanner, PlannerConfig
from weather_gym.tracks import TRACKS, load_track


def _straight(width=3.5, spacing=4.0, length=40.0):
    x = np.arange(1.0, length, spacing)
    cones = np.r_[np.c_[x, np.full_like(x, width / 2)], np.c_[x, np.full_like(x, -width / 2)]]
    classes = np.r_[np.zeros(len(x), int), np.ones(len(x), int)]
    return cones, classes


def test_straight_track_centre_line():
    cones, classes = _straight()
    plan = CenterlinePlanner().plan(cones, classes, pose=(0.0, 0.0, 0.0))
    assert np.abs(plan.path[:, 1]).max() < 0.05
    assert plan.path[0, 0] < 0.0 < plan.path[-1, 0]  # starts behind the car, leads ahead
    assert plan.length > 18.0  # cones up to 25 m away (the planner's radius)
    assert plan.half_width == pytest.approx(1.75, abs=0.01)


@pytest.mark.parametrize("keep", [0, 1])
def test_one_side_missing_is_offset_by_the_half_width(keep):
    cones, classes = _straight(width=4.0)
    planner = CenterlinePlanner()
    for _ in range(20):  # learns the 2 m half-width (running average over plans with both sides)
        planner.plan(cones, classes, pose=(0.0, 0.0, 0.0))
    plan = planner.plan(cones[classes == keep], classes[classes == keep], pose=(0.0, 0.0, 0.0))
    assert np.abs(plan.path[:, 1]).max() < 0.1
    assert plan.length > 18.0
    assert len(plan.midpoints) == 0 and len(plan.virtual) > 0


def test_pose_and_frames():
    cones, classes = _straight()
    yaw = 0.7
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    moved = cones @ rot.T + [3.0, -4.0]
    a = CenterlinePlanner().plan(cones, classes, pose=(0.0, 0.0, 0.0))
    b = CenterlinePlanner().plan(moved, classes, pose=(3.0, -4.0, yaw))
    assert np.allclose(a.path @ rot.T + [3.0, -4.0], b.path)


def test_nothing_mapped_gives_an_empty_plan_and_bad_input_raises():
    plan = CenterlinePlanner().plan(np.zeros((0, 2)), np.zeros(0, int), pose=(0.0, 0.0, 0.0))
    assert plan.path.shape == (0, 2) and plan.length == 0.0
    with pytest.raises(ValueError, match="classes"):
        CenterlinePlanner().plan(np.zeros((3, 2)), np.zeros(2, int), pose=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="max_width"):
        PlannerConfig(min_width=5.0, max_width=4.0)


TRACKDRIVE = [n for n in TRACKS.names() if n not in ("random", "skidpad", "acceleration")] + ["random:5"]


@pytest.mark.parametrize("name", TRACKDRIVE)
def test_plan_stays_inside_the_cones_on_every_track(name):
    """With every cone mapped, the path the controller uses (first 15 m) keeps the car inside the cone
    lines from anywhere on the track, and is close to the track's centre line."""
    track = load_track(name)
    planner = CenterlinePlanner()
    margins, deviations = [], []
    for s in np.arange(0.0, track.length, 3.0):
        x, y, h = track.point_at(s)
        plan = planner.plan(track.cones_xy, track.cone_classes, pose=(float(x), float(y), float(h)))
        assert plan.length > 12.0, f"{name}: path of {plan.length:.1f} m at s={s:.0f}"
        ahead = plan.path[1:]  # the first point is the backward extension
        arc = np.r_[0.0, np.cumsum(np.hypot(*np.diff(ahead, axis=0).T))]
        near = ahead[arc <= 15.0]
        left, right = track.boundary_distance(near[:, 0], near[:, 1], s_hint=s + 7.0, window=12.0)
        margins.append(float(np.minimum(left, right).min()))
        deviations.append(float(np.median(distance_to_polyline(near, track.centerline, True))))
    margins = np.array(margins)
    # the car is 1.2 m wide: its centre must stay 0.6 m inside the cone lines
    assert margins.min() > 0.6, f"{name}: path {0.6 - margins.min():.2f} m too close to the cones at s={3 * margins.argmin()}"
    assert np.median(deviations) < 0.25, f"{name}: median deviation from the centre line {np.median(deviations):.2f} m"
