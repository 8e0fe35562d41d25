"""``EpisodeBag`` / ``weather-gym lap --bag``: an episode as an MCAP rosbag2 that both rosbags and
mcap's own reader read back, frames and cones byte for byte."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap_ros2")

from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.interfaces import QosDurability  # noqa: E402

from weather_gym.camera.config import CameraConfig  # noqa: E402
from weather_gym.cli import main  # noqa: E402
from weather_gym.core.errors import OutputExistsError  # noqa: E402
from weather_gym.perception.cones import pack_cones  # noqa: E402
from weather_gym.ros.episode_bag import ConeNoise, EpisodeBag  # noqa: E402
from weather_gym.ros.messages import CONE_FIELDS  # noqa: E402

CAM = CameraConfig(width=64, height=40)
TRUE_XY = np.array([[1.0, 2.0], [3.0, -1.5], [5.0, 0.5]])
TRUE_CLS = np.array([0, 1, 3])


def _episode(out, steps=3, images="raw"):
    rng = np.random.default_rng(0)
    frames = []
    with EpisodeBag(out, camera=CAM, cones_xy=TRUE_XY, cone_classes=TRUE_CLS, weathered=True, images=images,
                    noise=ConeNoise(0.05, 0.04, 0.01)) as bag:
        for i in range(steps):
            clear = rng.integers(0, 255, (40, 64, 3), dtype=np.uint8)
            wet = rng.integers(0, 255, (40, 64, 3), dtype=np.uint8)
            cones, mask = pack_cones(classes=np.array([0, 1]), ranges=np.array([4.0, 9.0]),
                                     bearings=np.array([0.2, -0.3]), scores=np.array([0.9, 0.8]),
                                     boxes=np.array([[10, 10, 14, 18.0], [40, 12, 42, 16.0]]), camera=CAM, max_cones=8)
            bag.add(i / 30, clear=clear, weathered=wet, cones=cones, mask=mask, pose=(i * 0.5, 0.1, 0.05 * i),
                    speed=15.0, yaw_rate=0.3, odom=(i * 0.49, 0.1, 0.05 * i))
            frames.append((clear, wet, cones[mask.astype(bool)]))
    return frames


def test_both_readers_read_the_episode_back(tmp_path):
    frames = _episode(tmp_path / "lap")
    # rosbags
    with AnyReader([tmp_path / "lap"]) as r:
        conns = {c.topic: c for c in r.connections}
        assert conns["/tf_static"].ext.offered_qos_profiles[0].durability == QosDurability.TRANSIENT_LOCAL
        got = {}
        for c, ns, raw in r.messages():
            got.setdefault(c.topic, []).append((ns, r.deserialize(raw, c.msgtype)))
    assert [ns for ns, _ in got["/camera/image_raw"]] == [0, 33333333, 66666667]
    for (clear, wet, _rows), (_, a), (_, b) in zip(frames, got["/camera/image_raw"], got["/camera/image_weathered"],
                                                  strict=True):
        assert a.encoding == "rgb8" and np.array_equal(a.data.reshape(40, 64, 3), clear)
        assert np.array_equal(b.data.reshape(40, 64, 3), wet)
    info = got["/camera/camera_info"][0][1]
    assert info.k[0] == pytest.approx(CAM.fx) and info.k[2] == pytest.approx(CAM.cx) and info.header.frame_id == "camera_optical"
    (_, gt), = got["/ground_truth/cones"]
    assert [(c.point.x, c.point.y) for c in gt.blue_cones] == [(1.0, 2.0)]
    assert len(gt.yellow_cones) == 1 and len(gt.big_orange_cones) == 1 and gt.header.frame_id == "map"
    # mcap's own reader: the same cones
    with open(next((tmp_path / "lap").glob("*.mcap")), "rb") as f:
        cones = [m for _, ch, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
                 if ch.topic == "/perception/cones"]
    assert len(cones) == 3
    for msg, (_, _, rows) in zip(cones, frames, strict=True):
        assert msg.header.frame_id == "base_footprint"
        (blue,), (yellow,) = msg.blue_cones, msg.yellow_cones
        assert (blue.point.x, blue.point.y) == (float(rows[0, 11]), float(rows[0, 12]))
        assert (yellow.point.x, yellow.point.y) == (float(rows[1, 11]), float(rows[1, 12]))
        cov = np.array(blue.covariance).reshape(2, 2)
        sr, sb = 0.05 + 0.04 * 4.0, 4.0 * 0.01  # along and across the line of sight at bearing 0.2
        c, s = np.cos(0.2), np.sin(0.2)
        rot = np.array([[c, -s], [s, c]])
        np.testing.assert_allclose(cov, rot @ np.diag([sr**2, sb**2]) @ rot.T, rtol=1e-6)
        assert all(len(getattr(msg, f)) == 0 for f in CONE_FIELDS[2:])


def test_jpeg_frames_and_an_error_leaves_nothing(tmp_path):
    _episode(tmp_path / "lap", steps=2, images="jpeg")
    with AnyReader([tmp_path / "lap"]) as r:
        assert {c.topic for c in r.connections} >= {"/camera/image_raw/compressed", "/camera/image_weathered/compressed"}
    with pytest.raises(OutputExistsError):
        _episode(tmp_path / "lap")
    with pytest.raises(KeyboardInterrupt), EpisodeBag(tmp_path / "cut", camera=CAM, cones_xy=TRUE_XY,
                                                      cone_classes=TRUE_CLS) as bag:
        bag.add(0.0, clear=np.zeros((40, 64, 3), np.uint8), pose=(0, 0, 0), speed=0.0, yaw_rate=0.0)
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lap"]


def test_a_detector_lap_with_a_bag(tmp_path, capsys):
    bag = tmp_path / "lap_bag"
    code = main(["lap", "--agent", "mapper_pure_pursuit", "--weather", "droplets@3", "--max-steps", "6",
                 "--env-id", "WeatherGym/ConeTrackSmall-v0", "--bag", str(bag), "--bag-images", "raw"])
    out = capsys.readouterr().out
    assert code == 1 and f"bag: {bag} (MCAP rosbag2)" in out and "/perception/cones 7" in out
    with AnyReader([bag]) as r:
        imgs = {}
        for c, _, raw in r.messages():
            if c.topic.startswith("/camera/image"):
                imgs.setdefault(c.topic, []).append(r.deserialize(raw, c.msgtype).data)
    assert len(imgs["/camera/image_raw"]) == len(imgs["/camera/image_weathered"]) == 7
    assert not np.array_equal(imgs["/camera/image_raw"][3], imgs["/camera/image_weathered"][3])


def test_the_cone_covariance_is_the_mappers_noise_model():
    from weather_gym.agents.mapper import MapperConfig

    m = MapperConfig()
    assert ConeNoise() == ConeNoise(m.range_std, m.range_std_rel, m.bearing_std)


def test_an_evaluation_cell_writes_its_bag_and_the_same_metrics(tmp_path):
    import math

    from weather_gym.lab.evaluation.evaluate import EvalConfig, bag_name, make_cells, run_cell

    cell, = make_cells(EvalConfig(effects=("droplets",), severities=(3,), seeds=(0,), tracks=("hairpin",),
                                  env_id="WeatherGym/ConeTrackSmall-v0", max_steps=5))
    plain, bagged = run_cell(cell), run_cell(cell, bag_dir=str(tmp_path), bag_images="raw")
    same = {k: (a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b)))
            for k, (a, b) in ((k, (plain[k], bagged[k])) for k in plain) if not k.endswith("latency_ms")}  # wall clock
    assert all(same.values()), same  # keeping the frame for the bag changes nothing the agent does
    with AnyReader([tmp_path / bag_name(cell)]) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
    assert counts["/camera/image_weathered"] == counts["/perception/cones"] == counts["/odom"] == 6


def test_same_episode_same_bytes(tmp_path):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        _episode(tmp_path / d / "lap", steps=2, images="jpeg")
    files = [sorted((tmp_path / d / "lap").iterdir()) for d in ("a", "b")]
    assert [p.name for p in files[0]] == ["lap.mcap", "metadata.yaml"]
    assert [p.read_bytes() for p in files[0]] == [p.read_bytes() for p in files[1]]
