"""``weather-gym degrade IN_BAG OUT_BAG``: the camera weathered as one episode (state from the bag's
odometry and camera info), everything else byte for byte, read back with rosbags and with mcap's reader."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap_ros2")

from _make_bags import DT, NOTE, T0, frame, ros1_bag, ros2_bag, strip_definition  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402

from weather_gym.cli import main  # noqa: E402
from weather_gym.core.errors import FileFormatError, InputError, OutputExistsError, OutputPathError  # noqa: E402
from weather_gym.ros.degrade import degrade_bag  # noqa: E402
from weather_gym.ros.messages import image_to_rgb  # noqa: E402
from weather_gym.weather import parse_weather  # noqa: E402

WEATHER = "droplets:0.6:persistent=true,motion_blur:0.8"


def _read(path):
    """{topic: [(receive ns, raw bytes)]}, {topic: (type, qos, msgdef)} read with rosbags."""
    msgs, conns = {}, {}
    with AnyReader([path]) as r:
        for c in r.connections:
            conns[c.topic] = (c.msgtype, getattr(c.ext, "offered_qos_profiles", None), c.msgdef.data)
        for c, ns, raw in r.messages():
            msgs.setdefault(c.topic, []).append((ns, bytes(raw)))
    return msgs, conns


def _frames(path, topic):
    with AnyReader([path]) as r:
        conns = [c for c in r.connections if c.topic == topic]
        return [(r.deserialize(raw, c.msgtype), c.msgtype) for c, _, raw in r.messages(connections=conns)]


def test_raw_mcap_bag_weathered_as_one_episode_with_the_odometry(tmp_path):
    src = ros2_bag(tmp_path / "in", storage="mcap", n=5, w=96, h=64, compressed=False, encoding="bgr8", pad=2)
    res = degrade_bag(src, tmp_path / "out", weather=parse_weather(WEATHER), seed=3)
    assert (res.frames, res.odometry, res.kind, res.storage) == (5, "/odom", "rosbag2", "mcap")
    a, ca = _read(src)
    b, cb = _read(tmp_path / "out")
    assert ca == cb  # topics, types, QoS profiles and definitions kept
    for topic in ("/odom", "/note", "/cam/camera_info"):
        assert a[topic] == b[topic]  # byte for byte, same receive times
    assert [ns for ns, _ in a["/cam/image_raw"]] == [ns for ns, _ in b["/cam/image_raw"]]
    # the same weather run by hand, frame after frame, with the state of the latest odometry before each frame
    run = parse_weather(WEATHER).start(3)
    for i, (msg, mtype) in enumerate(_frames(tmp_path / "out", "/cam/image_raw")):
        state = {"speed": 8.0 + i, "yaw_rate": 0.5 - 0.2 * i, "fx": 80.0}
        want = run(frame(i, 96, 64), state=state)
        assert msg.encoding == "bgr8" and msg.step == 96 * 3
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == T0 + i * DT + 20
        assert np.array_equal(image_to_rgb(msg, mtype), want)
        assert not np.array_equal(want, frame(i, 96, 64))


def test_mcap_reader_reads_the_weathered_bag(tmp_path):
    src = ros2_bag(tmp_path / "in", storage="mcap", n=3)
    degrade_bag(src, tmp_path / "out", weather=parse_weather("droplets@3"))
    topics = {}
    with open(next((tmp_path / "out").glob("*.mcap")), "rb") as f:
        for _, channel, message, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, msg))
    assert sorted(topics) == ["/cam/camera_info", "/cam/image_raw/compressed", "/note", "/odom"]
    assert [t for t, _ in topics["/cam/image_raw/compressed"]] == [T0 + i * DT + 20 for i in range(3)]
    assert [m.text for _, m in topics["/note"]] == ["note 0", "note 1", "note 2"]
    img = cv2.imdecode(np.frombuffer(bytes(topics["/cam/image_raw/compressed"][0][1].data), np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (64, 96, 3)


def test_sqlite_and_ros1_bags_keep_their_kind(tmp_path):
    src = ros2_bag(tmp_path / "in", storage="sqlite3", n=2, odom=False)
    res = degrade_bag(src, tmp_path / "out", weather=parse_weather("low_light@2"))
    assert (res.storage, res.odometry, (tmp_path / "out" / "out.db3").is_file()) == ("sqlite3", None, True)
    assert _read(src)[0]["/note"] == _read(tmp_path / "out")[0]["/note"]
    src1 = ros1_bag(tmp_path / "in.bag", n=2)
    res1 = degrade_bag(src1, tmp_path / "out.bag", weather=parse_weather("low_light@2"))
    assert (res1.kind, res1.frames) == ("rosbag1", 2)
    a, ca = _read(src1)
    b, cb = _read(tmp_path / "out.bag")
    assert ca == cb and a["/camera/camera_info"] == b["/camera/camera_info"]


def test_same_seed_same_bytes(tmp_path):
    src = ros2_bag(tmp_path / "in", n=3)
    for name in ("a", "b"):
        degrade_bag(src, tmp_path / name, weather=parse_weather("droplets@3"), seed=7)
    assert _read(tmp_path / "a")[0] == _read(tmp_path / "b")[0]


def test_type_without_definition_is_left_out_with_a_note(tmp_path, capsys):
    src = ros2_bag(tmp_path / "in", storage="sqlite3", n=2)
    strip_definition(src, NOTE)
    assert main(["degrade", str(src), str(tmp_path / "out"), "--weather", "droplets@2", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "left out /note: type my_msgs/msg/Note has no definition" in out
    assert "speed and yaw rate from /odom" in out
    assert "/note" not in _read(tmp_path / "out")[1]


def test_damaged_bag_leaves_nothing(tmp_path):
    src = ros2_bag(tmp_path / "in", n=4, compressed=False)
    mcap = next(src.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    data[3000:6000] = b"\xff" * 3000  # inside the first chunk: the summary still opens
    mcap.write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match=str(src.name)):
        degrade_bag(src, tmp_path / "out", weather=parse_weather("droplets@2"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]  # no output, no temporary folder


def test_outputs_are_checked(tmp_path):
    src = ros2_bag(tmp_path / "in", n=2)
    w = parse_weather("droplets@1")
    with pytest.raises(InputError, match="must not be the input"):
        degrade_bag(src, src / "inner", weather=w)
    with pytest.raises(OutputPathError, match="folder"):
        degrade_bag(src, tmp_path / "out.mcap", weather=w)
    (tmp_path / "notes").mkdir()
    with pytest.raises(OutputPathError, match="not a rosbag2 bag"):
        degrade_bag(src, tmp_path / "notes", weather=w, overwrite=True)
    degrade_bag(src, tmp_path / "out", weather=w)
    with pytest.raises(OutputExistsError):
        degrade_bag(src, tmp_path / "out", weather=w)
    before = _read(tmp_path / "out")[0]
    degrade_bag(src, tmp_path / "out", weather=parse_weather("droplets@3"), seed=1, overwrite=True)
    assert _read(tmp_path / "out")[0] != before


@pytest.mark.parametrize("mode", ["MESSAGE", "FILE"])
def test_a_zstd_compressed_bag_is_read(tmp_path, monkeypatch, mode):
    from rosbags import rosbag2
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    plain_open = rosbag2.Writer.open

    def compressed_open(self):
        self.set_compression(CompressionMode[mode], CompressionFormat.ZSTD)
        return plain_open(self)

    monkeypatch.setattr(rosbag2.Writer, "open", compressed_open)
    src = ros2_bag(tmp_path / "in", storage="mcap", n=2)
    monkeypatch.setattr(rosbag2.Writer, "open", plain_open)
    res = degrade_bag(src, tmp_path / "out", weather=parse_weather("droplets@3"))
    assert res.frames == 2 and _read(src)[0]["/note"] == _read(tmp_path / "out")[0]["/note"]
