"""Cones of unknown colour (a LiDAR's): the mapper keeps them without a colour, the planner sides them by geometry."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.agents.mapper import ConeMapper
from weather_gym.agents.planner import CenterlinePlanner
from weather_gym.core.cone_spec import UNKNOWN_CLASS
from weather_gym.tracks import load_track


def test_mapper_keeps_unknown_colour():
    mapper = ConeMapper()
    for _ in range(5):
        mapper.update(np.array([[10.0, 1.5], [10.0, -1.5]]), np.array([UNKNOWN_CLASS, 0]), np.ones(2),
                      pose=(0.0, 0.0, 0.0))
    m = mapper.map(confirmed_only=True)
    order = np.argsort(m.xy[:, 1])
    assert m.classes[order].tolist() == [0, UNKNOWN_CLASS]  # sorted by y: the blue cone is on the right here
    assert m.class_prob[order][0].sum() == 1.0 and m.class_prob[order][1].sum() == 0.0


def _offsets(track_name: str) -> np.ndarray:
    """The largest distance from the centre line of each plan's first 10 m, planning every 2 m along a
    lap on the cones a car would have mapped by then (8 m behind to 20 m ahead), all of unknown colour."""
    track = load_track(track_name)
    xy = np.asarray(track.cones_xy, float)
    s_cone = np.array([track.project(x, y).s for x, y in xy])
    planner = CenterlinePlanner()
    worst = []
    for s in np.arange(0.0, track.length, 2.0):
        pose = track.point_at(float(s))
        ds = (s_cone - s + track.length / 2) % track.length - track.length / 2
        sel = (ds > -8) & (ds < 20)
        plan = planner.plan(xy[sel], np.full(int(sel.sum()), UNKNOWN_CLASS), pose)
        near = [abs(float(track.project(x, y).lateral)) for x, y in plan.path
                if np.hypot(x - pose[0], y - pose[1]) < 10.0]
        worst.append(max(near) if near else np.inf)
    return np.asarray(worst)


@pytest.mark.parametrize("track", ["small_track", "peanut"])
def test_planner_sides_unknown_cones_by_geometry_through_the_lap(track):
    worst = _offsets(track)
    assert np.median(worst) < 0.3 and (worst < 1.0).mean() >= 0.8


def test_coloured_cones_plan_as_before():
    track = load_track("small_track")
    xy, cls = np.asarray(track.cones_xy, float), np.asarray(track.cone_classes)
    pose = track.point_at(30.0)
    a = CenterlinePlanner().plan(xy, cls, pose).path
    planner = CenterlinePlanner()
    planner.plan(xy, cls, track.point_at(28.0))  # a previous plan changes nothing for coloured cones
    np.testing.assert_allclose(planner.plan(xy, cls, pose).path, a)
