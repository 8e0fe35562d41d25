"""``ConeMemory``: this frame's cones plus the confirmed cones seen in the last second, in the car frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from weather_gym.agents.cone_memory import ConeMemory, ConeMemoryConfig
from weather_gym.agents.mapper import MapperConfig
from weather_gym.camera.config import CameraConfig
from weather_gym.perception.cones import FIELD, cone_list_space, unpack_cones

N = cone_list_space()["mask"].shape[0]


def obs_of(cones_xy_cls, pose=(0.0, 0.0, 0.0), speed=0.0):
    """A cone-list observation with cones at car-frame (x, y) of class c, the car at odometry ``pose``."""
    cones = np.zeros((N, len(FIELD)), np.float32)
    mask = np.zeros(N, np.int8)
    for i, (x, y, c) in enumerate(cones_xy_cls):
        cones[i, c] = 1.0
        cones[i, FIELD["x_body"]], cones[i, FIELD["y_body"]] = x, y
        cones[i, FIELD["range"]] = math.hypot(x - 0.6, y)
        cones[i, FIELD["bearing"]] = math.atan2(y, x - 0.6)
        cones[i, FIELD["score"]] = 0.9
        mask[i] = 1
    return {"cones": cones, "mask": mask, "state": np.array([speed, 0.0, *pose], np.float32)}


def test_a_confirmed_cone_stays_where_it_is_in_the_world_after_it_is_no_longer_detected():
    memory = ConeMemory()
    for _ in range(4):
        out = memory(obs_of([(8.0, 2.0, 0), (8.0, -2.0, 1)]))
    assert out["mask"].sum() == 2  # detected now: passed on as they are, nothing added
    # the car moved 3 m forward and turned 90 degrees left; the yellow cone is seen where it now is
    # (world (8, -2) from the car at (3, 0) facing +y: car frame (-2, -5)), the blue one is missed
    out = memory(obs_of([(-2.0, -5.0, 1)], pose=(3.0, 0.0, math.pi / 2)))
    got = unpack_cones(out["cones"], out["mask"])
    assert got["classes"].tolist() == [0, 1]  # the remembered blue cone is the nearer one
    np.testing.assert_allclose([got["x_body"][0], got["y_body"][0]], [2.0, -5.0], atol=1e-5)  # world (8, 2)
    assert got["score"][0] == pytest.approx(1.0)  # the colour vote's share
    assert got["range"][0] == pytest.approx(math.hypot(2.0 - 0.6, -5.0), abs=1e-5)
    assert got["bearing"][0] == pytest.approx(math.atan2(-5.0, 1.4), abs=1e-5)
    assert not out["cones"][0, FIELD["x1"]:FIELD["y2"] + 1].any()  # no box: it is not in this frame
    np.testing.assert_array_equal(out["cones"][1], obs_of([(-2.0, -5.0, 1)])["cones"][0])  # detection as given


def test_the_yellow_cone_of_the_current_frame_is_kept_and_the_list_is_sorted_by_range():
    memory = ConeMemory()
    for _ in range(4):
        memory(obs_of([(12.0, 2.0, 0), (5.0, -2.0, 1)]))
    out = memory(obs_of([(5.0, -2.0, 1)]))  # the far blue cone is missed
    got = unpack_cones(out["cones"], out["mask"])
    assert got["classes"].tolist() == [1, 0] and np.all(np.diff(got["range"]) >= 0)
    assert out["cones"].dtype == np.float32 and out["cones"].shape == (N, len(FIELD))
    assert out["mask"].dtype == np.int8 and out["mask"][:2].all() and not out["mask"][2:].any()


def test_one_false_detection_is_never_remembered_and_the_input_is_not_changed():
    memory = ConeMemory()
    phantom = obs_of([(6.0, 0.0, 2)])
    before = {k: v.copy() for k, v in phantom.items()}
    memory(phantom)
    empty = obs_of([])
    for _ in range(5):
        assert memory(empty)["mask"].sum() == 0
    for k in before:
        np.testing.assert_array_equal(phantom[k], before[k])


def test_old_cones_and_cones_behind_the_car_are_left_out_and_reset_forgets():
    memory = ConeMemory(ConeMemoryConfig(max_age=5))
    for _ in range(4):
        memory(obs_of([(10.0, 2.0, 0)]))
    empty = obs_of([])
    assert [int(memory(empty)["mask"].sum()) for _ in range(6)] == [1, 1, 1, 1, 1, 0]  # 5 steps, then gone

    memory = ConeMemory()
    for _ in range(4):
        memory(obs_of([(10.0, 2.0, 0)]))
    assert memory(obs_of([], pose=(9.0, 0.0, 0.0)))["mask"].sum() == 1  # 1 m ahead of the car
    assert memory(obs_of([], pose=(10.5, 0.0, 0.0)))["mask"].sum() == 0  # beside/behind: max_behind 0
    memory = ConeMemory(ConeMemoryConfig(max_behind=1.0))
    for _ in range(4):
        memory(obs_of([(10.0, 2.0, 0)]))
    assert memory(obs_of([], pose=(10.5, 0.0, 0.0)))["mask"].sum() == 1
    memory.reset()
    assert memory(empty)["mask"].sum() == 0


@pytest.mark.parametrize(("duplicate_dist", "listed"), [(1.0, 1), (0.5, 2)])
def test_a_remembered_cone_next_to_a_detection_is_that_cone_not_a_second_one(duplicate_dist, listed):
    memory = ConeMemory(ConeMemoryConfig(duplicate_dist=duplicate_dist))
    for _ in range(4):
        memory(obs_of([(10.0, 2.0, 0)]))
    # odometry error: the same cone is now seen 0.8 m from where the map has it, beyond the mapper's gate
    out = memory(obs_of([(10.0, 2.8, 0)], pose=(0.0, 0.0, 0.0)))
    assert out["mask"].sum() == listed


def test_detections_beyond_the_detection_range_are_left_out():
    far = obs_of([(5.0, 2.0, 0), (40.0, 2.0, 1), (60.0, -2.0, 1)])
    cut = ConeMemory(ConeMemoryConfig(detection_range=30.0))(far)
    assert unpack_cones(cut["cones"], cut["mask"])["classes"].tolist() == [0]
    assert ConeMemory()(far)["mask"].sum() == 3  # no cut by default


def test_the_camera_sets_the_mount_for_range_and_bearing():
    camera = CameraConfig(mount_x=1.0)
    memory = ConeMemory(camera=camera)
    assert memory.mapper.config.mount_x == 1.0 and memory.mapper.config.hfov_deg == camera.hfov_deg
    for _ in range(4):
        memory(obs_of([(10.0, 0.0, 0)]))
    out = memory(obs_of([]))
    got = unpack_cones(out["cones"], out["mask"])
    assert got["range"][0] == pytest.approx(9.0)


def test_the_config_round_trips_through_json_and_bad_values_are_named():
    cfg = ConeMemoryConfig(max_age=12, mapper=MapperConfig(min_hits=3))
    assert ConeMemoryConfig.from_dict(cfg.to_dict()) == cfg
    assert ConeMemoryConfig.from_dict({}) == ConeMemoryConfig()
    with pytest.raises(ValueError, match="max_ages"):
        ConeMemoryConfig.from_dict({"max_ages": 3})
    with pytest.raises(ValueError, match=r"cone_memory\.mapper: unknown key\(s\) \['min_hit'\]; valid keys: .*'min_hits'"):
        ConeMemoryConfig.from_dict({"mapper": {"min_hit": 3}})
    with pytest.raises(ValueError, match="max_age"):
        ConeMemoryConfig(max_age=0)
    with pytest.raises(ValueError, match="max_behind"):
        ConeMemoryConfig(max_behind=-1.0)
    with pytest.raises(ValueError, match="table"):
        ConeMemoryConfig.from_dict([1, 2])
    with pytest.raises(ValueError, match="detection_range"):
        ConeMemoryConfig(detection_range=0.0)
    assert ConeMemoryConfig.from_dict({"detection_range": None}).detection_range is None
