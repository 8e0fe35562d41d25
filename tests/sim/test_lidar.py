"""The LiDAR sensor: its config, the fast scan against every beam through rayTestBatch, determinism."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from weather_gym.core.errors import InputError
from weather_gym.core.point_cloud import label_id
from weather_gym.lab.bench.lidar import compare_scans
from weather_gym.sim.config import SimConfig
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.sim.world import World
from weather_gym.tracks import load_track


@pytest.fixture(scope="module")
def world():
    w = World(load_track("small_track"), sim=SimConfig(renderer="none"))
    yield w
    w.close()


def test_presets_have_their_data_sheet_figures():
    hdl = LidarConfig.hdl32e()
    assert (hdl.channels, hdl.columns, hdl.rays, hdl.rate_hz, hdl.max_range) == (32, 2250, 72000, 10.0, 100.0)
    assert hdl.elevations_deg[0] == pytest.approx(-30.67) and hdl.elevations_deg[-1] == pytest.approx(10.67)
    ss = LidarConfig.solid_state()
    assert (ss.hfov_deg, ss.columns, ss.channels) == (120.0, 600, 125) and not ss.spinning
    assert ss.azimuths_deg[0] == pytest.approx(-59.9) and ss.azimuths_deg[-1] == pytest.approx(59.9)


@pytest.mark.parametrize("kwargs, word", [({"channels": 0}, "channels"), ({"h_res_deg": -1.0}, "h_res_deg"),
                                          ({"max_range": float("nan")}, "max_range"),
                                          ({"vfov_low_deg": 20.0, "vfov_high_deg": 10.0}, "vfov_high_deg"),
                                          ({"channels": 512, "h_res_deg": 0.01}, "beams per scan")])
def test_bad_configs_name_the_field(kwargs, word):
    with pytest.raises(InputError, match=word):
        LidarConfig(**kwargs)


@pytest.mark.parametrize("cfg", [LidarConfig(), LidarConfig.solid_state()], ids=["hdl32e", "solid_state"])
@pytest.mark.parametrize("s", [0.0, 37.0, 95.0])
def test_culled_cast_equals_every_beam_cast(world, cfg, s):
    """Without the analytic cone hits, the beams cast are culled to those near a cone's hull: bit for bit."""
    world.reset(world.track.point_at(s))
    sensor = world.lidar(cfg)
    sensor.analytic = False
    try:
        fast, naive = world.lidar_scan(cfg), world.lidar_scan(cfg, naive=True)
    finally:
        sensor.analytic = True
    assert len(fast) == len(naive) and (fast.cone >= 0).sum() > 20
    np.testing.assert_array_equal(fast.ring, naive.ring)
    np.testing.assert_array_equal(fast.cone, naive.cone)
    np.testing.assert_array_equal(fast.label, naive.label)
    np.testing.assert_allclose(fast.xyz, naive.xyz, atol=1e-4)
    np.testing.assert_allclose(fast.intensity, naive.intensity, atol=1e-5)


@pytest.mark.parametrize("cfg", [LidarConfig(), LidarConfig.solid_state()], ids=["hdl32e", "solid_state"])
@pytest.mark.parametrize("s", [0.0, 37.0, 95.0])
def test_analytic_cone_hits_match_every_beam_cast(world, cfg, s):
    """The default scan (cone hits on the collision hull, analytically) against every beam through
    rayTestBatch: the same returns but for grazing beams (at most 2 % of the cone returns), cone ranges
    within 3 mm at the 99th percentile and 5 cm at worst (Bullet's ray test is iterative: its hits lie 0.9-2 mm
    outside the hull)."""
    world.reset(world.track.point_at(s))
    fast, naive = world.lidar_scan(cfg), world.lidar_scan(cfg, naive=True)
    d = compare_scans(fast, naive, cfg)
    on_cones = int((naive.cone >= 0).sum())
    assert on_cones > 20 and d["different"] <= 0.02 * on_cones
    assert np.percentile(d["range_diff"], 99) < 0.003 and d["range_diff"].max() < 0.05
    ground = naive.cone < 0
    assert abs(int((fast.cone < 0).sum()) - int(ground.sum())) <= 0.02 * on_cones


def test_a_knocked_cone_is_scanned_where_it_lies(world):
    world.reset(world.track.point_at(0.0))
    cfg = LidarConfig()
    seen = np.unique(world.lidar_scan(cfg).cone)
    i = int(seen[seen >= 0][0])
    # tip the cone over by hand: the world's record of knocked cones drives the fast path's window
    body = world._cone_bodies[i]
    x, y = world.cone_xy[i]
    quat = p.getQuaternionFromEuler([1.2, 0.0, 0.0])
    p.resetBasePositionAndOrientation(body, [float(x), float(y) + 0.2, 0.15], quat, physicsClientId=world.client)
    rot = np.asarray(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
    world._cone_tilt[i] = (np.array([x, y + 0.2, 0.15]) - rot[:, 2] * world._cone_com_z[i], rot)
    world._cone_xy[i] = (x, y + 0.2)
    try:
        fast, naive = world.lidar_scan(cfg), world.lidar_scan(cfg, naive=True)
        assert (fast.cone == i).sum() > 0 and (fast.cone == i).sum() == (naive.cone == i).sum()
        knocked = naive.cone == i  # cast through rayTestBatch: as the naive scan has it
        np.testing.assert_allclose(np.sort(fast.ranges[fast.cone == i]), np.sort(naive.ranges[knocked]), atol=1e-4)
        d = compare_scans(fast, naive, cfg)
        assert d["different"] <= 0.02 * int((naive.cone >= 0).sum())
    finally:
        world._dynamic_cones.add(i)
        world.reset(world.track.point_at(0.0))


def test_returns_are_where_the_geometry_says(world):
    cfg = LidarConfig()
    world.reset(world.track.point_at(20.0))
    scan = world.lidar_scan(cfg)
    z_car = scan.xyz[:, 2] + cfg.mount_z
    ground = scan.label == label_id("ground")
    assert np.abs(z_car[ground]).max() < 1e-4
    cones = scan.label == label_id("cone")
    assert (z_car[cones] > -1e-4).all() and (z_car[cones] < 0.52).all()
    r = scan.ranges
    assert r.min() >= cfg.min_range - 1e-4 and r.max() <= cfg.max_range + 1e-4
    assert ((scan.intensity >= 0) & (scan.intensity <= 1)).all()
    # the stripes: a cone's returns show two reflectivities (body and stripe)
    assert len(np.unique(scan.reflectivity[cones])) >= 2


def test_same_seed_same_scan_and_noise_only_with_a_generator(world):
    cfg = LidarConfig()
    world.reset(world.track.point_at(5.0))
    a = world.lidar_scan(cfg, np.random.default_rng(3))
    b = world.lidar_scan(cfg, np.random.default_rng(3))
    clean = world.lidar_scan(cfg)
    assert a.equals(b) and not a.equals(clean)
    d = a.ranges - clean.ranges
    assert abs(float(d.std()) - cfg.range_noise_m) < 0.002
