"""Cones from LiDAR points: found where the cones are, coloured from the stripes near the car (unknown beyond),
and the cone list carries that."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import UNKNOWN_CLASS
from weather_gym.core.errors import InputError
from weather_gym.core.point_cloud import PointCloud
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
                out.append((cfg, cloud, np.c_[c * d[:, 0] + si * d[:, 1], -si * d[:, 0] + c * d[:, 1]],
                            world.cone_classes[ids[n >= 2]]))
    finally:
        world.close()
    return out


def test_near_cones_are_found_in_clear_air(scans):
    for cfg, cloud, truth, _ in scans:
        cones = cones_from_points(cloud, cfg)
        assert (cones_from_points(cloud, cfg, LidarConeConfig(stripe_colour=False))["classes"] == UNKNOWN_CLASS).all()
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


def test_colour_from_the_stripes_near_the_car(scans):
    """The HDL-32E's rings cross a small cone's stripe only within about 7 m (mounted 0.3 m up): cones read
    there get their true colour, farther ones stay unknown; no cone gets a wrong colour."""
    right = {"HDL-32E": 0, "solid-state 120x25": 0}
    for cfg, cloud, truth, cls in scans:
        cones = cones_from_points(cloud, cfg)
        for x, y, c, r in zip(cones["x_body"], cones["y_body"], cones["classes"], cones["ranges"]):
            d = np.hypot(truth[:, 0] - x, truth[:, 1] - y)
            if c == UNKNOWN_CLASS or d.min() > 0.5:
                continue
            assert c == cls[d.argmin()], (cfg.name, float(r))
            right[cfg.name] += 1
            assert cfg.name != "HDL-32E" or r < 8.0
    assert right["HDL-32E"] >= 4 and right["solid-state 120x25"] >= 4, right


def test_stripe_contrast_tells_blue_from_yellow():
    cfg = LidarConfig()
    z = np.array([0.06, 0.09, 0.16, 0.17, 0.25, 0.28])  # body, body, stripe, stripe, body, body (car frame)
    xyz = np.c_[np.full(6, 5.0), np.linspace(0.0, 0.05, 6), z - cfg.mount_z]
    for body, stripe, want in ((0.25, 0.85, 0), (0.6, 0.05, 1), (0.5, 0.5, UNKNOWN_CLASS)):
        inten = np.where((z > 0.14) & (z < 0.2), stripe, body)
        cloud = PointCloud.from_arrays(xyz=xyz, intensity=inten, ring=np.zeros(6))
        assert cones_from_points(cloud, cfg)["classes"].tolist() == [want]


def test_ground_alone_gives_no_cone(scans):
    cfg, cloud, _, _ = scans[0]
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


def test_stripe_band_is_the_simulated_cones():
    from weather_gym.perception.lidar_cones import STRIPE_BAND
    from weather_gym.sim.textures import STRIPES

    assert all(STRIPES[c] == (STRIPE_BAND,) for c in ("blue", "yellow", "orange"))
