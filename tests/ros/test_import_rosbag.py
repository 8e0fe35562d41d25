"""``weather-gym dataset import rosbag``: bags made by rosbags' own writers (another camera size,
compressed and raw frames, row padding, grey frames, ROS 1), the frames and timestamps read back."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

pytest.importorskip("rosbags")

from _make_bags import DT, T0, frame, ros1_bag, ros2_bag  # noqa: E402

from weather_gym.cli import main  # noqa: E402
from weather_gym.core.errors import FileFormatError, InputError, OutputExistsError  # noqa: E402
from weather_gym.lab.datasets.coco import load_coco  # noqa: E402
from weather_gym.lab.datasets.import_rosbag import import_rosbag  # noqa: E402
from weather_gym.ros.camera import Window  # noqa: E402


def test_compressed_mcap_bag_imports_every_nth_frame_with_stamps_and_intrinsics(tmp_path):
    bag = ros2_bag(tmp_path / "run", storage="mcap", n=6, w=96, h=64)
    r = import_rosbag(bag, tmp_path / "ds", window=Window(every=2))
    assert (r["frames"], r["size"], r["kind"], r["storage"]) == (3, [96, 64], "rosbag2", "mcap")
    assert r["camera_info"] == "/cam/camera_info" and r["intrinsics"] == "camera_info"
    ds = load_coco(tmp_path / "ds")
    assert len(ds) == 3 and ds.data["annotations"] == []
    for k, im in enumerate(ds.images):
        i = 2 * k
        assert im["stamp_ns"] == im["bag_time_ns"] == T0 + i * DT + 20
        assert im["intrinsics"] == {"fx": 80.0, "fy": 80.0, "cx": 49.5, "cy": 31.5}
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(frame(i, 96, 64), cv2.COLOR_RGB2BGR))
        want = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        assert np.array_equal(ds.image(k), want)  # the decoded JPEG, stored losslessly
    info = json.loads((tmp_path / "ds" / "annotations.json").read_text())["info"]
    assert info["format"] == "rosbag" and info["labels"].startswith("none")


@pytest.mark.parametrize(("encoding", "pad"), [("bgr8", 4), ("rgb8", 0), ("mono8", 3)])
def test_raw_sqlite_bag_frames_are_the_recorded_pixels(tmp_path, encoding, pad):
    bag = ros2_bag(tmp_path / "run", storage="sqlite3", n=4, w=72, h=40, compressed=False, encoding=encoding, pad=pad)
    r = import_rosbag(bag, tmp_path / "ds", window=Window(start_s=0.04, end_s=0.14))  # frames 1 and 2
    assert r["frames"] == 2 and r["encodings"] == {encoding: 2}
    ds = load_coco(tmp_path / "ds")
    for k, i in enumerate((1, 2)):
        want = frame(i, 72, 40)
        if encoding == "mono8":
            want = np.repeat(cv2.cvtColor(want, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=2)
        assert np.array_equal(ds.image(k), want)
        assert ds.images[k]["stamp_ns"] == T0 + i * DT + 20


def test_ros1_bag_imports(tmp_path):
    r = import_rosbag(ros1_bag(tmp_path / "run.bag", n=3, w=80, h=48), tmp_path / "ds")
    assert (r["frames"], r["kind"], r["intrinsics"]) == (3, "rosbag1", "camera_info")
    assert np.array_equal(load_coco(tmp_path / "ds").image(2), frame(2, 80, 48))


@pytest.mark.parametrize("kind", ["mcap", "sqlite3", "ros1"])
def test_truncated_bag_is_a_typed_error_and_nothing_is_written(tmp_path, kind):
    if kind == "ros1":
        bag = file = ros1_bag(tmp_path / "run.bag", n=3)
    else:
        bag = ros2_bag(tmp_path / "run", storage=kind, n=3)
        file = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    file.write_bytes(file.read_bytes()[: file.stat().st_size // 2])
    with pytest.raises(FileFormatError, match="damaged, truncated"):
        import_rosbag(bag, tmp_path / "ds")
    assert not (tmp_path / "ds").exists()


def test_an_interrupted_import_resumes(tmp_path, monkeypatch):
    from weather_gym.lab.datasets import import_rosbag as mod

    bag = ros2_bag(tmp_path / "run", n=5)
    real, calls = mod.write_image, []

    def flaky(path, image, **kw):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(path)
        return real(path, image, **kw)

    monkeypatch.setattr(mod, "write_image", flaky)
    with pytest.raises(KeyboardInterrupt):
        import_rosbag(bag, tmp_path / "ds")
    monkeypatch.setattr(mod, "write_image", real)
    with pytest.raises(OutputExistsError, match="interrupted import"):
        import_rosbag(bag, tmp_path / "ds")
    with pytest.raises(InputError, match="other settings"):
        import_rosbag(bag, tmp_path / "ds", window=Window(every=2), resume=True)
    r = import_rosbag(bag, tmp_path / "ds", resume=True)
    assert (r["frames"], r["resumed"]) == (5, 3) and len(load_coco(tmp_path / "ds")) == 5


def test_topic_checks_and_an_existing_dataset(tmp_path):
    bag = ros2_bag(tmp_path / "run", n=2)
    with pytest.raises(InputError, match="carries nav_msgs/msg/Odometry"):
        import_rosbag(bag, tmp_path / "ds", topic="/odom")
    with pytest.raises(InputError, match="not in"):
        import_rosbag(bag, tmp_path / "ds", topic="/nope")
    with pytest.raises(FileFormatError, match="no frames"):
        import_rosbag(bag, tmp_path / "ds", window=Window(start_s=50.0))
    assert not (tmp_path / "ds").exists()
    import_rosbag(bag, tmp_path / "ds")
    with pytest.raises(OutputExistsError):
        import_rosbag(bag, tmp_path / "ds")
    assert import_rosbag(bag, tmp_path / "ds", overwrite=True)["frames"] == 2


def test_cli_import(tmp_path, capsys):
    bag = ros2_bag(tmp_path / "run", n=4)
    assert main(["dataset", "import", "rosbag", str(bag), "--out", str(tmp_path / "ds"), "--every", "3",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "imported 2 frames (96x64) of /cam/image_raw/compressed" in out and "labels: none" in out
    assert main(["dataset", "import", "yolo", str(bag), "--out", str(tmp_path / "x"), "--topic", "/cam"]) == 2
    assert "go with the rosbag format" in capsys.readouterr().err


def test_without_rosbags_the_error_names_the_pip_command(tmp_path, monkeypatch):
    from weather_gym.core.errors import MissingDependencyError
    from weather_gym.ros import _deps

    monkeypatch.setattr(_deps, "_LIB", False)
    bag = ros2_bag(tmp_path / "run", n=1)
    with pytest.raises(MissingDependencyError, match=r"pip install 'weather-gym\[ros\]'"):
        import_rosbag(bag, tmp_path / "ds")
    assert not (tmp_path / "ds").exists()
