"""Cones from LiDAR points: found where the cones are, of unknown colour, and the cone list carries that."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import UNKNOWN_CLASS
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import pack_cones, unpack_cones
from weather_gym.perception.lidar_cones import LidarConeConfig, cones_from_points
from weather_gym.perception.lidar_scoring import LidarScoring
from weather_gym.sim.config import SimConfig
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.sim.world import World
from weather_gym.tracks import load_track


@pytest.fixture(scope="module")
def scans():
    world = World(load_track("small_track"), sim=SimConfig(renderer="none"))
    out = []
    try:
        for s in (0.0, 25.0, 60.0, 110.0):
            world.reset(world.track.point_at(s))
            for cfg in (LidarConfig(), LidarConfig.solid_state()):
                cloud = world.lidar_scan(cfg, np.random.default_rng(0))
                ids, n = np.unique(cloud.cone[cloud.cone >= 0], return_counts=True)
                x, y, yaw = world.car.pose
                d = world.cone_xy[ids[n >= 2]] - (x, y)
                c, si = np.cos(yaw), np.sin(yaw)
                out.append((cfg, cloud, np.c_[c * d[:, 0] + si * d[:, 1], -si * d[:, 0] + c * d[:, 1]]))
    finally:
        world.close()
    return out


def test_near_cones_are_found_in_clear_air(scans):
    for cfg, cloud, truth in scans:
        cones = cones_from_points(cloud, cfg)
        assert (cones["classes"] == UNKNOWN_CLASS).all()
        near = np.hypot(truth[:, 0] - cfg.mount_x, truth[:, 1]) < 10.0
        s = LidarScoring()
        s.add(det_xy=np.c_[cones["x_body"], cones["y_body"]], gt_xy=truth[near],
              gt_ranges=np.hypot(truth[near, 0] - cfg.mount_x, truth[near, 1]), det_ranges=cones["ranges"])
        r = s.result()
        assert r.recall >= 0.8 and r.position_error_m < 0.06, (cfg.name, r)
        # every detection is a real cone (at any range)
        s2 = LidarScoring()
        s2.add(det_xy=np.c_[cones["x_body"], cones["y_body"]], gt_xy=truth,
               gt_ranges=np.hypot(truth[:, 0], truth[:, 1]), det_ranges=cones["ranges"])
        assert s2.result().precision == 1.0


def test_ground_alone_gives_no_cone(scans):
    cfg, cloud, _ = scans[0]
    assert cones_from_points(cloud.select(cloud.cone < 0), cfg).count == 0


def test_bad_tuning_is_refused():
    with pytest.raises(InputError, match="min_points"):
        LidarConeConfig(min_points=0)
    with pytest.raises(InputError, match="max_height_m"):
        LidarConeConfig(min_height_m=0.7)


def test_unknown_colour_through_the_cone_list():
    cones, mask = pack_cones(classes=np.array([UNKNOWN_CLASS, 1]), ranges=np.array([4.0, 6.0]),
                             bearings=np.zeros(2), scores=np.ones(2), boxes=np.zeros((2, 4)), camera=CameraConfig(),
                             max_cones=4)
    assert cones[0, :4].sum() == 0 and cones[1, 1] == 1
    assert unpack_cones(cones, mask)["classes"].tolist() == [UNKNOWN_CLASS, 1]
    with pytest.raises(InputError, match="unknown colour"):
        pack_cones(classes=np.array([-2]), ranges=np.ones(1), bearings=np.zeros(1), scores=np.ones(1),
                   boxes=np.zeros((1, 4)), camera=CameraConfig())
