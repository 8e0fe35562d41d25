"""Videos: H.264 through PyAV (fallback mp4v with a warning), RecordVideo of the weathered camera view."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.core.errors import MissingDependencyError
from weather_gym.viz import video as video_mod
from weather_gym.viz.video import VideoWriter, h264_available

av = pytest.importorskip("av")


def _read(path):
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        frames = [f.to_ndarray(format="rgb24") for f in c.decode(s)]
        return s.codec_context.name, frames


def _frames(n=12, h=47, w=63):
    out = []
    for i in range(n):
        f = np.zeros((h, w, 3), np.uint8)
        f[:, :, 0] = 20 * i
        f[10:30, 5 + i: 25 + i] = (30, 200, 60)
        out.append(f)
    return out


def test_video_is_h264_with_every_frame_and_appears_only_when_closed(tmp_path):
    assert h264_available()
    path = tmp_path / "lap.mp4"
    frames = _frames()
    writer = VideoWriter(path, fps=30)
    for f in frames:
        writer.write(f)
    assert not path.exists()  # written to a hidden partial file first
    writer.close()
    assert not list(tmp_path.glob(".*partial*"))
    codec, got = _read(path)
    assert codec == "h264" and writer.codec == "h264" and len(got) == len(frames)
    assert got[0].shape == (48, 64, 3)  # odd sizes padded by one replicated row/column
    for i in (0, 5, 11):  # lossy, but the pictures are the ones written, in order
        assert np.abs(got[i][:47, :63].astype(int) - frames[i]).mean() < 6
    with pytest.raises(FileExistsError, match="--overwrite"):
        VideoWriter(path)
    with pytest.raises(ValueError, match="frame size changed"):
        w = VideoWriter(tmp_path / "b.mp4")
        w.write(frames[0])
        w.write(np.zeros((10, 10, 3), np.uint8))


def test_without_h264_the_writer_falls_back_to_mp4v_with_a_warning(tmp_path, monkeypatch):
    monkeypatch.setattr(video_mod, "h264_available", lambda: False)
    with pytest.warns(RuntimeWarning, match="pip install av"):
        writer = VideoWriter(tmp_path / "old.mp4")
    with writer:
        for f in _frames(4):
            writer.write(f)
    assert writer.codec == "mp4v" and _read(tmp_path / "old.mp4")[0] == "mpeg4"
    with pytest.raises(MissingDependencyError, match="pip install av"):
        VideoWriter(tmp_path / "x.mp4", codec="h264")


@pytest.mark.slow
def test_record_video_shows_the_weather_the_agent_sees(make_env, tmp_path):
    from weather_gym.wrappers import RecordVideo

    means = {}
    for weather in ("clear", {"dim": 0.7}):
        env = make_env(render_mode="rgb_array", render_view="camera", weather=weather)
        env = RecordVideo(env, tmp_path / str(bool(weather != "clear")), episode_trigger=lambda n: n == 0)
        obs, _ = env.reset(seed=0)
        np.testing.assert_array_equal(env.render(), obs["image"])  # render() is the observation's frame
        for _ in range(20):
            obs, *_ = env.step(np.array([0.0, 0.5], np.float32))
        np.testing.assert_array_equal(env.render(), obs["image"])
        env.close()
        (path,) = env.videos
        codec, frames = _read(path)
        assert codec == "h264" and len(frames) == 21 and frames[0].shape[:2] == obs["image"].shape[:2]
        means[weather != "clear"] = float(np.mean(frames))
    assert means[True] < 0.5 * means[False]  # dim 0.7 keeps 30 % of the light: the video shows it
    with pytest.raises(FileExistsError):
        env = RecordVideo(make_env(render_mode="rgb_array", render_view="camera"), tmp_path / "True",
                          episode_trigger=lambda n: True)
        env.reset(seed=0)


def test_record_video_needs_frames():
    import gymnasium as gym

    from weather_gym.wrappers import RecordVideo

    with pytest.raises(ValueError, match="render_mode='rgb_array'"):
        RecordVideo(gym.make("CartPole-v1"), "unused")


_FULL_DISK = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG, as on a full disk
resource.setrlimit(resource.RLIMIT_FSIZE, (20000, 20000))
from weather_gym.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("suffix", [".mp4", ".avi"])
def test_a_full_disk_is_a_typed_error_and_leaves_no_file(tmp_path, suffix):
    """The disk fills while a video is written (a file size limit in a child process stands in for a full
    disk: the same failed write, EFBIG instead of ENOSPC): exit status 2, an ``error:`` line, no
    temporary file and no half video."""
    import subprocess
    import sys

    import cv2

    rng = np.random.default_rng(0)
    src = tmp_path / "in" / "clip.mp4"
    src.parent.mkdir()
    vw = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (160, 120))
    for _ in range(30):
        vw.write(rng.integers(0, 256, (120, 160, 3), dtype=np.uint8))
    vw.release()
    out = tmp_path / "out"
    out.mkdir()
    r = subprocess.run([sys.executable, "-c", _FULL_DISK, "degrade", str(src), str(out / f"d{suffix}"), "--weather",
                        "noise:0.5", "--quiet"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "error: cannot write" in r.stderr and "Traceback" not in r.stderr
    assert list(out.iterdir()) == []


def test_a_video_is_not_started_on_a_full_disk(tmp_path, monkeypatch):
    from weather_gym.core.errors import OutputPathError

    class Full:
        f_bavail, f_frsize = 10, 4096

    monkeypatch.setattr(video_mod.os, "statvfs", lambda _p: Full)
    with pytest.raises(OutputPathError, match="no space left"):
        with VideoWriter(tmp_path / "v.mp4") as v:
            v.write(_frames(1)[0])
    assert list(tmp_path.iterdir()) == []
