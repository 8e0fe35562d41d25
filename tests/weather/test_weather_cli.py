"""``weather-gym degrade`` (offline mode), ``weather-gym bench weather`` and the grid example."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import cv2
import numpy as np
import pytest

from weather_gym.cli import main
from weather_gym.weather import make, parse_weather
from weather_gym.weather.sample import sample_frame


def _write(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


def _read(path: Path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


@pytest.fixture
def frame():
    return sample_frame(94, 168, seed=0)[0]


def test_degrade_one_image(tmp_path, frame):
    src = tmp_path / "in.png"
    _write(src, frame)
    assert main(["degrade", str(src), str(tmp_path / "out.png"), "--weather", "dim:0.55"]) == 0
    np.testing.assert_array_equal(_read(tmp_path / "out.png"), make("dim", k=0.55)(frame))
    np.testing.assert_array_equal(_read(src), frame)  # input untouched
    outdir = tmp_path / "outdir"
    outdir.mkdir()
    assert main(["degrade", str(src), str(outdir), "--weather", "droplets:0.5,noise:0.2", "--seed", "3"]) == 0
    assert (outdir / "in.png").is_file()


def test_degrade_never_overwrites(tmp_path, frame, capsys):
    src = tmp_path / "in.png"
    _write(src, frame)
    assert main(["degrade", str(src), str(src), "--weather", "dim:0.5"]) == 2
    assert "overwrite the input" in capsys.readouterr().err
    np.testing.assert_array_equal(_read(src), frame)
    out = tmp_path / "out.png"
    _write(out, frame)
    assert main(["degrade", str(src), str(out), "--weather", "dim:0.5"]) == 2
    assert "pass --overwrite" in capsys.readouterr().err
    assert main(["degrade", str(src), str(out), "--weather", "dim:0.5", "--overwrite"]) == 0
    assert main(["degrade", str(src), str(out), "--weather", "dim:0.5", "--force"]) == 0  # old name
    assert "--force is deprecated" in capsys.readouterr().err


def test_degrade_a_folder_mirrors_names_and_resumes(tmp_path, frame, capsys):
    src = tmp_path / "images"
    for rel in ("a.png", "sub/b.png", "sub/c.jpg"):
        _write(src / rel, frame)
    (src / "notes.txt").write_text("not an image")
    out = tmp_path / "wet"
    args = ["degrade", str(src), str(out), "--weather", "droplets:0.8", "--seed", "1", "--quiet"]
    assert main(args) == 0
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == \
        ["a.png", "sub/b.png", "sub/c.jpg"]
    a = _read(out / "a.png")
    (out / "sub" / "b.png").unlink()
    assert main(args) == 0
    assert "skipped 2" in capsys.readouterr().out
    np.testing.assert_array_equal(_read(out / "a.png"), a)
    # per-image seeds: the same image under another name gets other droplets, same name same droplets
    assert not np.array_equal(_read(out / "sub" / "b.png"), a)
    assert main(["degrade", str(src), str(src / "inside"), "--weather", "dim:0.1"]) == 2
    assert "inside it" in capsys.readouterr().err


def test_degrade_a_folder_with_depth(tmp_path):
    img, depth = sample_frame(94, 168, seed=1)
    _write(tmp_path / "images" / "000001.png", img)
    (tmp_path / "depth").mkdir()
    cv2.imwrite(str(tmp_path / "depth" / "000001.png"), (depth * 1000).astype(np.uint16))
    assert main(["degrade", str(tmp_path / "images"), str(tmp_path / "out"), "--weather", "fog:0.7",
                 "--depth", str(tmp_path / "depth"), "--quiet"]) == 0
    expected = make("fog", k=0.7)(img, depth=np.round(depth * 1000).astype(np.uint16) / np.float32(1000))
    assert np.abs(_read(tmp_path / "out" / "000001.png").astype(int) - expected).max() <= 1


def test_degrade_a_video_with_persistent_droplets(tmp_path, frame):
    src = tmp_path / "lap.avi"
    h, w = frame.shape[:2]
    vw = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"MJPG"), 10, (w, h))
    for i in range(6):
        vw.write(cv2.cvtColor(np.roll(frame, i, axis=1), cv2.COLOR_RGB2BGR))
    vw.release()
    out = tmp_path / "lap_wet.avi"
    assert main(["degrade", str(src), str(out), "--weather", "droplets:0.7:persistent=true",
                 "--quiet"]) == 0
    cap = cv2.VideoCapture(str(out))
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == 6 and not list(tmp_path.glob(".*partial*"))


@pytest.mark.parametrize(("argv", "message"), [
    ([], "give the weather with --weather SPEC"),
    (["--weather", "dim"], "must be NAME:K"),
    (["--weather", "dim:1.5"], "outside"),
    (["--weather", "dim:0.5:stops"], "must be PARAM=VALUE"),
    (["--weather", "[{\"name\": \"dim\""], "not valid JSON"),
    (["--weather", "sleet:0.3"], "unknown weather effect"),
])
def test_degrade_errors(tmp_path, frame, capsys, argv, message):
    src = tmp_path / "in.png"
    _write(src, frame)
    assert main(["degrade", str(src), str(tmp_path / "o.png"), *argv]) == 2
    assert message in capsys.readouterr().err
    assert main(["degrade", str(tmp_path / "missing.png"), str(tmp_path / "o.png"), "--weather", "dim:0.2"]) == 2


def test_bench_weather_runs_and_prints_the_table(tmp_path, capsys):
    out = tmp_path / "bench.md"
    presets = [(p, parse_weather(p)) for p in ("droplets@2", "droplets@3", "droplets@4", "low_light@1", "low_light@2",
                                                "low_light@3", "low_light@4")]  # a row per preset that does something
    assert main(["bench", "weather", "--sizes", "96x64", "--repeats", "2", "--warmup", "0", "--batch", "2",
                 "--effects", "droplets,dim,noise", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    for row in ("frame copy (np.copyto)", "study droplets", "study dim: Pillow", "droplets (k=0.55)",
                "dim physical", "noise (k=0.5)", "speed-up vs study",
                *(f"{p} ({e.mode} k={e.k})" for p, e in presets)):
        assert row in text
    assert "droplets@1 " not in text  # k = 0: a copy
    assert out.read_text().strip() == text.strip()
    assert main(["bench", "weather", "--sizes", "64x48", "--repeats", "2", "--warmup", "0", "--batch", "0",
                 "--effects", "vignette", "--cold", "--cpu-time"]) == 0
    text = capsys.readouterr().out
    assert "(`--cold`)" in text and "vignette (k=0.5)" in text and "loop of" not in text
    assert "CPU time of the thread per call (`--cpu-time`)" in text
    assert main(["bench", "weather", "--sizes", "96by64"]) == 2


def test_grid_example_on_the_synthetic_scene(tmp_path):
    path = Path(__file__).resolve().parents[2] / "examples" / "weather_grid.py"
    spec = importlib.util.spec_from_file_location("weather_grid", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    img, depth = sample_frame(94, 168, seed=0)
    g = mod.grid(img, depth, {"speed": 5.0}, tile_w=84)
    assert g.shape[1] == 190 + 84 * 4 and g.shape[0] == 28 + len(mod.ROWS) * 47
    out = tmp_path / "grid.png"
    assert mod.main(["--synthetic", "--out", str(out)]) == 0 and out.stat().st_size > 0
    assert mod.main(["--synthetic", "--out", str(out)]) == 2  # never overwritten without --overwrite


def test_degrade_a_folder_stops_at_an_unreadable_image_unless_told_to_skip(tmp_path, frame, capsys):
    src = tmp_path / "images"
    for rel in ("a.png", "b.png", "c.png"):
        _write(src / rel, frame)
    (src / "b.png").write_bytes((src / "b.png").read_bytes()[:60])  # cut short
    out = tmp_path / "out"
    assert main(["degrade", str(src), str(out), "--weather", "dim:0.5", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "b.png" in err and "--skip-unreadable" in err
    assert main(["degrade", str(src), str(out), "--weather", "dim:0.5", "--quiet", "--skip-unreadable"]) == 0
    text = capsys.readouterr().out
    assert "skipped 1 unreadable image(s): b.png" in text
    assert sorted(p.name for p in out.iterdir()) == ["a.png", "c.png"]
