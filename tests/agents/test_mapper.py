"""ConeMapper on synthetic cone observations from a known track and odometry (no simulator)."""

from __future__ import annotations

import numpy as np
import pytest
from agent_sim import SyntheticCones

from weather_gym.agents.mapper import ConeMapper, MapperConfig
from weather_gym.camera.config import CameraConfig
from weather_gym.perception.cones import unpack_cones
from weather_gym.tracks import load_track


def _observe(per: SyntheticCones, pose):
    cones, mask = per(pose)
    d = unpack_cones(cones, mask)
    return np.c_[d["x_body"], d["y_body"]], d["classes"], d["score"], d["range"], d["bearing"]


def _drive_along(track, per: SyntheticCones, mapper: ConeMapper, metres: float, step: float = 0.3):
    """Feed the mapper from poses on the centre line every ``step`` metres (true pose = odometry);
    returns how many frames each track cone was in view."""
    frames = np.zeros(len(track.cones_xy), int)
    for s in np.arange(2.0, metres, step):
        x, y, h = track.point_at(s)
        pose = (float(x), float(y), float(h))
        xy, cls, score, r, b = _observe(per, pose)
        mapper.update(xy, cls, score, pose=pose, ranges=r, bearings=b)
        frames[per.visible(pose)] += 1
    return frames


def _match(map_xy, true_xy):
    d = np.hypot(*(map_xy[:, None, :] - true_xy[None, :, :]).transpose(2, 0, 1))
    return d.argmin(axis=1), d.min(axis=1)


def test_perfect_observations_map_every_seen_cone_once():
    track = load_track("small_track")
    mapper = ConeMapper()
    frames = _drive_along(track, SyntheticCones(track, max_range=15.0), mapper, 60.0)
    m = mapper.map(confirmed_only=True)
    idx, err = _match(m.xy, track.cones_xy)
    assert err.max() < 0.02
    # each cone seen in min_hits frames or more is mapped exactly once, and nothing else
    assert sorted(idx.tolist()) == np.flatnonzero(frames >= mapper.config.min_hits).tolist()
    assert np.array_equal(m.classes, track.cone_classes[idx])
    assert np.all(m.class_confidence == 1.0)


def test_noisy_observations_average_out_and_report_their_uncertainty():
    track = load_track("small_track")
    per = SyntheticCones(track, max_range=15.0, seed=3, range_noise=0.05, bearing_noise=0.01)
    mapper = ConeMapper(MapperConfig(range_std_rel=0.05, bearing_std=0.01))
    _drive_along(track, per, mapper, 60.0)
    m = mapper.map(confirmed_only=True)
    _, err = _match(m.xy, track.cones_xy)
    # single measurements at 10 m have ~0.5 m of range error; the fused map is far better
    assert np.median(err) < 0.15
    assert err[m.hits >= 10].max() < 0.4
    summary = m.summary()
    assert 0.0 < summary["mean_position_std_m"] < 0.3
    # the reported std is of the right size: most true errors lie within 3 sigma
    assert np.mean(err < 3 * m.position_std) > 0.8


def test_uncertainty_shrinks_with_repeated_observations():
    mapper = ConeMapper()
    stds = []
    for _ in range(10):
        mapper.update(np.array([[12.0, 2.0]]), np.array([0]), np.array([1.0]), pose=(0.0, 0.0, 0.0))
        stds.append(float(mapper.map().position_std[0]))
    assert len(mapper) == 1
    assert stds[-1] < 0.5 * stds[0]


def test_single_false_detection_never_becomes_a_cone():
    mapper = ConeMapper(MapperConfig(min_hits=3, max_misses=3))
    real = np.array([[8.0, 2.0], [8.0, -2.0]])
    for k in range(12):
        xy = real if k != 2 else np.vstack([real, [[10.0, 0.5]]])  # one phantom cone in frame 2
        mapper.update(xy, np.array([0, 1, 1][: len(xy)]), np.ones(len(xy)), pose=(0.0, 0.0, 0.0))
    m = mapper.map(confirmed_only=True)
    assert len(m) == 2
    assert np.allclose(np.sort(m.xy[:, 1]), [-2.0, 2.0])
    assert len(mapper) == 2  # the phantom was in view, missed 3 times and dropped


def test_detections_beyond_max_range_map_nothing_until_the_car_is_near():
    # far boxes are a few pixels tall and their ranges come out long: a cone seen at 24 m (reported
    # 2 m too far, as the realistic world's were) must not be mapped there; seen from 15 m it is
    mapper = ConeMapper()
    assert mapper.config.max_range == 20.0
    for _ in range(6):
        mapper.update(np.array([[26.6, 0.0]]), np.array([0]), np.ones(1), pose=(0.0, 0.0, 0.0))
    assert len(mapper) == 0
    for _ in range(6):
        mapper.update(np.array([[15.6, 0.0]]), np.array([0]), np.ones(1), pose=(9.0, 0.0, 0.0))
    m = mapper.map(confirmed_only=True)
    assert m.xy.round(1).tolist() == [[24.6, 0.0]]
    with pytest.raises(ValueError, match="max_range"):
        MapperConfig(max_range=0.0)


def test_colour_is_decided_by_vote():
    mapper = ConeMapper()
    for k in range(10):  # 3 of 10 frames call the blue cone yellow
        mapper.update(np.array([[9.0, 1.8]]), np.array([1 if k in (1, 4, 7) else 0]), np.array([0.9]),
                      pose=(0.0, 0.0, 0.0))
    m = mapper.map()
    assert m.classes.tolist() == [0]
    assert m.class_confidence[0] == pytest.approx(0.7)


def test_close_cones_stay_separate_and_association_is_global():
    # two cones 0.9 m apart (tight corners have them): the Hungarian assignment keeps both
    mapper = ConeMapper()
    cones = np.array([[10.0, 1.5], [10.9, 1.5]])
    rng = np.random.default_rng(0)
    for _ in range(8):
        mapper.update(cones + rng.normal(0, 0.05, cones.shape), np.array([0, 0]), np.ones(2), pose=(0.0, 0.0, 0.0))
    m = mapper.map(confirmed_only=True)
    assert len(m) == 2 and np.allclose(np.sort(m.xy[:, 0]), [10.0, 10.9], atol=0.1)
    assert sorted(mapper.last_assignment.tolist()) == [0, 1]


def test_map_is_in_the_odometry_frame():
    mapper = ConeMapper()
    pose = (5.0, -2.0, np.pi / 2)  # facing +y
    for _ in range(4):
        mapper.update(np.array([[10.0, 0.0]]), np.array([1]), np.array([1.0]), pose=pose)
    assert np.allclose(mapper.map(confirmed_only=True).xy, [[5.0, 8.0]], atol=1e-9)


def test_max_age_keeps_only_recently_seen_cones():
    mapper = ConeMapper()
    for _ in range(4):
        mapper.update(np.array([[10.0, 2.0]]), np.array([0]), np.ones(1), pose=(0.0, 0.0, 0.0))
    for _ in range(5):  # drive on; the cone is now behind (not in view, not a miss)
        mapper.update(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0), pose=(20.0, 0.0, 0.0))
    assert len(mapper.map(confirmed_only=True)) == 1
    assert len(mapper.map(confirmed_only=True, max_age=4)) == 0
    assert mapper.map().age.tolist() == [5]


def test_update_from_obs_reads_the_cone_list_and_validates_it():
    track = load_track("small_track")
    per = SyntheticCones(track, CameraConfig())
    cones, mask = per(track.start_pose)
    mapper = ConeMapper()
    state = np.array([0, 0, *track.start_pose], np.float32)
    m = mapper.update_from_obs({"cones": cones, "mask": mask, "state": state})
    assert len(m) == int(mask.sum()) > 0
    with pytest.raises(ValueError, match="obs\\['state'\\]"):
        mapper.update_from_obs({"cones": cones, "mask": mask})
    with pytest.raises(ValueError, match="state"):
        mapper.update_from_obs({"cones": cones, "mask": mask, "state": np.zeros(2)})
    with pytest.raises(ValueError, match="gate_max"):
        MapperConfig(gate_max=0.0)
