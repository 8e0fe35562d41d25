"""File names as they come (weather_gym.core._image_files): a name that is not UTF-8 is read, or refused with a
typed error naming it; never a signal. Every ``dataset import`` format and ``degrade`` (a file, a folder,
a video) run in a subprocess (a crash must not take pytest down) under a UTF-8 locale with strict stdio,
where printing such a name raised before."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

import weather_gym
from weather_gym.core._image_files import colour_conversions, opencv_name, read_image_file, shown
from weather_gym.core.errors import InputError
from weather_gym.lab.datasets.coco import load_coco, read_image

NAME = os.fsdecode(b"caf\xe9")  # Latin-1 'café': not UTF-8, held by Python as 'caf\udce9'
ROOT = Path(weather_gym.__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "LC_ALL": "C.UTF-8", "LANG": "C.UTF-8",
       "PYTHONIOENCODING": "utf-8:strict", "PYTHONUTF8": "0"}


def _image(path: Path, w: int = 160, h: int = 120) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    img = np.full((h, w, 3), 90, np.uint8)
    img[10:30, 10:20] = (200, 40, 40)
    path.write_bytes(cv2.imencode(path.suffix, img)[1].tobytes())
    return path


def _cli(*args: str | Path) -> subprocess.CompletedProcess:
    argv = [os.fsencode(a) if isinstance(a, Path) else a for a in args]
    return subprocess.run([sys.executable, "-m", "weather_gym.cli", *argv], env=ENV, capture_output=True, timeout=300)


def _kitti(s: Path) -> None:
    _image(s / "images" / f"{NAME}.png")
    (s / "labels").mkdir()
    (s / "labels" / f"{NAME}.txt").write_text("blue_cone 0.00 0 0.00 10 40 30 80 0 0 0 0 0 0 0.00\n")


def _yolo(s: Path) -> None:
    _image(s / "images" / f"{NAME}.png")
    (s / "labels").mkdir()
    (s / "labels" / f"{NAME}.txt").write_text("0 0.25 0.5 0.1 0.5\n")
    (s / "classes.txt").write_text("blue_cone\n")


def _darknet(s: Path) -> None:
    _image(s / f"{NAME}.jpg")
    (s / f"{NAME}.txt").write_text("0 0.25 0.5 0.1 0.5\n")
    (s / "obj.names").write_text("blue_cone\n")


def _coco(s: Path) -> None:
    _image(s / "images" / f"{NAME}.png")
    (s / "instances.json").write_text(json.dumps({  # the name as a Python tool writes it: "caf\udce9.png"
        "images": [{"id": 1, "file_name": f"{NAME}.png", "width": 160, "height": 120}],
        "categories": [{"id": 1, "name": "blue_cone"}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [10, 20, 30, 60]}]}))


def _supervisely(s: Path) -> None:
    s.mkdir(parents=True)
    (s / "meta.json").write_text(json.dumps({"classes": [{"title": "blue_cone", "shape": "rectangle",
                                                          "color": "#0000FF"}], "tags": []}))
    _image(s / "team" / "img" / f"{NAME}.jpg")
    (s / "team" / "ann").mkdir()
    (s / "team" / "ann" / f"{NAME}.jpg.json").write_text(json.dumps({
        "size": {"height": 120, "width": 160}, "objects": [{
            "id": 1, "classTitle": "blue_cone", "geometryType": "rectangle", "tags": [],
            "points": {"exterior": [[10, 20], [40, 80]], "interior": []}}]}))


SOURCES = {"kitti": ("kitti", _kitti), "yolo": ("yolo", _yolo), "darknet": ("yolo", _darknet),
           "coco": ("coco", _coco), "supervisely": ("supervisely", _supervisely)}


def test_helpers_read_any_name_and_refuse_by_name_what_opencv_opens_by_name(tmp_path):
    p = _image(tmp_path / f"{NAME}.png", 6, 4)
    assert read_image_file(p).shape == (4, 6, 3)
    assert read_image_file(os.fsencode(p), cv2.IMREAD_UNCHANGED).shape == (4, 6, 3)
    assert read_image(p).shape == (4, 6, 3)
    assert read_image_file(tmp_path / "missing.png") is None and read_image_file(tmp_path) is None
    (tmp_path / "text.png").write_text("not an image")
    assert read_image_file(tmp_path / "text.png") is None
    assert shown(p.name) == "caf\\xe9.png" and shown("plain.png") == "plain.png"
    with pytest.raises(InputError, match=r"caf\\xe9\.mp4.*not UTF-8"):
        opencv_name(tmp_path / f"{NAME}.mp4", what="video")
    assert opencv_name(tmp_path / "café.mp4") == str(tmp_path / "café.mp4")


@pytest.mark.parametrize("kind", sorted(SOURCES))
def test_every_importer_takes_a_name_that_is_not_utf8(kind, tmp_path):
    fmt, make = SOURCES[kind]
    src = tmp_path / NAME / "src"  # the folder's name is not UTF-8 either
    make(src)
    out = tmp_path / f"out{NAME}"
    run = _cli("dataset", "import", fmt, src, "--out", out, "--quiet")
    assert run.returncode == 0, run.stderr.decode(errors="replace")[-2000:]
    assert b"caf\xe9" in run.stdout  # the output folder printed as its bytes
    ds = load_coco(out)
    assert [Path(r["file_name"]).stem for r in ds.images] == [NAME]
    assert read_image(ds.root / ds.images[0]["file_name"]).shape == (120, 160, 3)


def test_degrade_a_file_and_a_folder_by_names_that_are_not_utf8(tmp_path):
    src = _image(tmp_path / NAME / f"{NAME}.png")
    run = _cli("degrade", src, tmp_path / f"o{NAME}.png", "--weather", "droplets:0.5", "--seed", "3", "--quiet")
    assert run.returncode == 0, run.stderr.decode(errors="replace")[-2000:]
    assert b"wrote" in run.stdout and b"caf\xe9.png" in run.stdout
    run = _cli("degrade", tmp_path / NAME, tmp_path / f"od{NAME}", "--weather", "droplets:0.5", "--seed", "3",
               "--quiet")
    assert run.returncode == 0, run.stderr.decode(errors="replace")[-2000:]
    assert b"wrote 1 image(s)" in run.stdout
    one, folder = tmp_path / f"o{NAME}.png", tmp_path / f"od{NAME}" / f"{NAME}.png"
    assert read_image_file(one).shape == (120, 160, 3)
    assert one.read_bytes() == folder.read_bytes()  # the same seed from the same name, in both modes
    assert not np.array_equal(read_image_file(one), read_image_file(src))


def test_degrade_a_video_whose_name_is_not_utf8_is_a_typed_error_naming_it(tmp_path):
    src = tmp_path / f"{NAME}.mp4"
    src.write_bytes(b"\x00" * 64)
    run = _cli("degrade", src, tmp_path / "out.mp4", "--weather", "fog:0.5", "--quiet")
    assert run.returncode == 2, run.stderr
    assert b"caf\\xe9.mp4" in run.stderr and b"not UTF-8" in run.stderr
    assert not (tmp_path / "out.mp4").exists()


def _png(path: Path, img: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(cv2.imencode(".png", img)[1].tobytes())
    return path


def test_colour_conversions_read_from_the_header(tmp_path):
    rgb = np.full((8, 10, 3), 120, np.uint8)
    assert colour_conversions(_png(tmp_path / "rgb.png", rgb)) == ()
    assert colour_conversions(_png(tmp_path / "grey.png", rgb[..., 0])) == ("grey",)
    assert colour_conversions(_png(tmp_path / "rgba.png", np.dstack([rgb, rgb[..., 0]]))) == ("alpha",)
    assert colour_conversions(_png(tmp_path / "deep.png", rgb.astype(np.uint16) * 257)) == ("16-bit",)
    deep_grey_alpha = np.dstack([rgb[..., :1], rgb[..., :1], rgb[..., :1], rgb[..., :1]]).astype(np.uint16)
    assert colour_conversions(_png(tmp_path / "dga.png", deep_grey_alpha)) == ("alpha", "16-bit")
    (tmp_path / "grey.jpg").write_bytes(cv2.imencode(".jpg", rgb[..., 0])[1].tobytes())
    assert colour_conversions(tmp_path / "grey.jpg") == ("grey",)  # through Pillow
    assert colour_conversions(tmp_path / "missing.png") == ()


def test_degrade_says_what_it_converted(tmp_path, capsys):
    from weather_gym.cli import main

    rgb = np.full((40, 60, 3), 120, np.uint8)
    src = tmp_path / "in"
    _png(src / "rgba16.png", np.dstack([rgb, rgb[..., 0]]).astype(np.uint16) * 257)
    _png(src / "grey.png", rgb[..., 0])
    _png(src / "plain.png", rgb)
    assert main(["degrade", str(src / "rgba16.png"), str(tmp_path / "one.png"), "--weather", "fog:0.3", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "note: " in err and "rgba16.png read as 8-bit RGB: alpha channel dropped (not composited), 16 bits" in err
    out = read_image_file(tmp_path / "one.png", cv2.IMREAD_UNCHANGED)
    assert out.dtype == np.uint8 and out.shape == (40, 60, 3)
    assert main(["degrade", str(src), str(tmp_path / "out"), "--weather", "fog:0.3", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert ("note: 2 image(s) read as 8-bit RGB: grey copied into R, G and B in 1, alpha channel dropped "
            "(not composited) in 1, 16 bits per channel reduced to 8 in 1") in err
    assert main(["degrade", str(src / "plain.png"), str(tmp_path / "p.png"), "--weather", "fog:0.3", "--quiet"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_dataset_import_says_which_frames_are_read_as_8bit_rgb(tmp_path, capsys):
    from weather_gym.cli import main

    rgb = np.full((120, 160, 3), 90, np.uint8)
    src = tmp_path / "src"
    _png(src / "images" / "a.png", np.dstack([rgb, rgb[..., 0]]))
    _png(src / "images" / "b.png", rgb.astype(np.uint16) * 257)
    _png(src / "images" / "c.png", rgb)
    (src / "labels").mkdir()
    for n in "abc":
        (src / "labels" / f"{n}.txt").write_text("0 0.25 0.5 0.1 0.5\n")
    (src / "classes.txt").write_text("blue_cone\n")
    assert main(["dataset", "import", "yolo", str(src), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert ("note: 2 frame(s) that are not 8-bit colour (stored as they are) read as 8-bit RGB: alpha channel "
            "dropped (not composited) in 1, 16 bits per channel reduced to 8 in 1") in err
    ds = load_coco(tmp_path / "out")
    assert ds.info["read_as_8bit_rgb"] == {"frames": 2, "alpha": 1, "16-bit": 1}
    assert ds.image(1).dtype == np.uint8 and ds.image(1).shape == (120, 160, 3)
