"""``dataset import`` bad input, table-driven: each case exits 2 with a typed error naming the culprit.

Clean means: exit status 2 and an ``error:`` line naming the file or option, no traceback, nothing
private quoted (a line of a file linked from outside the source), the source unchanged and nothing
written outside ``--out`` (an ``--out`` left with no dataset, and no frame of the private folder).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _import_sources as S  # noqa: E402

from weather_gym.cli import main  # noqa: E402


@dataclass(frozen=True)
class Case:
    id: str
    fmt: str
    build: Callable[[Path, Path], list[str]]
    """``build(src, tmp)`` makes the source in ``src`` (``tmp`` holds the private folder); returns extra args."""
    culprit: str
    """A regular expression the ``error:`` line must match."""


def _link(path: Path, target: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() or path.is_symlink():
        path.unlink()
    os.symlink(target, path)


def _yolo(change: Callable[[Path, Path], list[str] | None]) -> Callable[[Path, Path], list[str]]:
    def build(src: Path, tmp: Path) -> list[str]:
        S.yolo(src)
        extra = change(src, S.private(tmp))
        return extra if isinstance(extra, list) else []
    return build


def _with(maker: Callable[[Path], Path], change: Callable[[Path, Path], list[str] | None]):
    def build(src: Path, tmp: Path) -> list[str]:
        maker(src)
        extra = change(src, S.private(tmp))
        return extra if isinstance(extra, list) else []
    return build


def _latin1(path: Path, text: str = "blue_cone\ncône jaune\n") -> None:
    path.write_bytes(text.encode("latin-1"))


def _huge(shape: tuple[int, int]) -> Callable[[Path, Path], list[str] | None]:
    def change(src: Path, priv: Path) -> None:
        assert cv2.imwrite(str(src / "images" / "f1.png"), np.zeros(shape, np.uint8))
    return change


def _sly_ann(src: Path) -> Path:
    return src / "team_a" / "ann" / "x.jpg.json"


def _sly_edit(edit: Callable[[dict], None]) -> Callable[[Path, Path], None]:
    def change(src: Path, priv: Path) -> None:
        data = json.loads(_sly_ann(src).read_text())
        edit(data)
        _sly_ann(src).write_text(json.dumps(data))
    return change


LINK = r"is a symbolic link \(or lies under one\) that leads outside"
CASES = [
    # ---- links out of the source: named, never read
    Case("yolo-image-linked-out", "yolo", _yolo(lambda s, p: _link(s / "images" / "f1.png", p / "secret.png")),
         rf"images/f1.png {LINK}"),
    Case("yolo-images-folder-linked-out", "yolo",
         _yolo(lambda s, p: (_link(s / "images" / "more", p))), rf"images/more {LINK}"),
    Case("yolo-classes-linked-out", "yolo", _yolo(lambda s, p: (_link(s / "classes.txt", p / "secret.txt"),
                                                               ["--classes", "*=ignore"])[1]),
         rf"classes.txt {LINK}"),
    Case("yolo-label-linked-out", "yolo", _yolo(lambda s, p: _link(s / "labels" / "f0.txt", p / "secret.txt")),
         rf"labels/f0.txt {LINK}"),
    Case("yolo-data-yaml-linked-out", "yolo",
         _yolo(lambda s, p: ((s / "classes.txt").unlink(), _link(s / "data.yaml", p / "secret.txt"))[0]),
         rf"data.yaml {LINK}"),
    Case("darknet-label-linked-out", "yolo", _with(S.darknet, lambda s, p: _link(s / "a.txt", p / "secret.txt")),
         rf"a.txt {LINK}"),
    Case("kitti-calib-linked-out", "kitti",
         _with(S.yolo, lambda s, p: (_link(s / "calib" / "f0.txt", p / "secret.txt"),
                                     [(s / "labels" / f"f{i}.txt").write_text(
                                         "blue_cone 0 0 0 10 20 30 80 0 0 0 0 0 0 0\n") for i in (0, 1)])[0]),
         rf"calib/f0.txt {LINK}"),
    Case("coco-json-linked-out", "coco",
         _with(S.coco, lambda s, p: _link(s / "instances.json", p / "secret.txt")), rf"instances.json {LINK}"),
    Case("coco-image-linked-out", "coco",
         _with(S.coco, lambda s, p: _link(s / "images" / "f1.png", p / "secret.png")), rf"images/f1.png {LINK}"),
    Case("coco-file-name-leaves-source", "coco",
         _with(S.coco, lambda s, p: (s / "instances.json").write_text(
             (s / "instances.json").read_text().replace('"f1.png"', '"../../private/secret.png"'))),
         r"image 2 'file_name': '../../private/secret.png' leads outside"),
    Case("supervisely-meta-linked-out", "supervisely",
         _with(S.supervisely, lambda s, p: _link(s / "meta.json", p / "secret.txt")), rf"meta.json {LINK}"),
    Case("supervisely-ann-linked-out", "supervisely",
         _with(S.supervisely, lambda s, p: _link(_sly_ann(s), p / "secret.txt")), rf"ann/x.jpg.json {LINK}"),
    Case("supervisely-img-linked-out", "supervisely",
         _with(S.supervisely, lambda s, p: _link(s / "team_a" / "img" / "x.jpg", p / "secret.png")),
         rf"img/x.jpg {LINK}"),
    # ---- text that is not UTF-8
    Case("yolo-label-not-utf8", "yolo", _yolo(lambda s, p: _latin1(s / "labels" / "f1.txt", "0 0.5 0.5 0.1 0.1 é\n")),
         r"labels/f1.txt is not UTF-8 text \(byte 0xe9 at offset 18\)"),
    Case("yolo-classes-not-utf8", "yolo", _yolo(lambda s, p: _latin1(s / "classes.txt")),
         r"classes.txt is not UTF-8 text"),
    Case("coco-json-not-utf8", "coco", _with(S.coco, lambda s, p: (s / "instances.json").write_bytes(
        (s / "instances.json").read_text().replace("blue_cone", "cône").encode("latin-1"))),
         r"instances.json is not UTF-8 text"),
    Case("supervisely-ann-not-utf8", "supervisely",
         _with(S.supervisely, lambda s, p: _latin1(_sly_ann(s), '{"size": "é"}')), r"x.jpg.json is not UTF-8 text"),
    # ---- frames beyond the one frame-size bound (weather_gym/core/limits.py)
    Case("frame-20000x100", "yolo", _yolo(_huge((100, 20000))),
         r"images/f1.png: image is 20000x100 pixels; each side must be 8 to 16384 pixels"),
    Case("frame-60MP", "yolo", _yolo(_huge((7600, 8000))),
         r"images/f1.png: image is 8000x7600 = 61 MP; at most 40 MP"),
    # ---- malformed labels of the new formats
    Case("supervisely-no-meta", "supervisely", _with(S.supervisely, lambda s, p: (s / "meta.json").unlink()),
         r"no meta.json"),
    Case("supervisely-class-not-in-meta", "supervisely",
         _with(S.supervisely, _sly_edit(lambda d: d["objects"][0].update(classTitle="purple_cone"))),
         r"x.jpg.json: object 0: class 'purple_cone' is not among the classes of .*meta.json"),
    Case("supervisely-bad-exterior", "supervisely",
         _with(S.supervisely, _sly_edit(lambda d: d["objects"][0]["points"].update(exterior=[[1, 2]]))),
         r"x.jpg.json: object 0: a rectangle needs points.exterior"),
    Case("supervisely-size-disagrees", "supervisely",
         _with(S.supervisely, _sly_edit(lambda d: d.update(size={"height": 10, "width": 10}))),
         r"x.jpg is 160x120 but its labels state 10x10"),
    Case("supervisely-missing-ann", "supervisely", _with(S.supervisely, lambda s, p: _sly_ann(s).unlink()),
         r"x.jpg: its Supervisely annotation .*x.jpg.json is missing"),
    Case("supervisely-class-unmapped", "supervisely", _with(S.supervisely, lambda s, p: ["--classes", "blue_cone=blue"]),
         r"class 'large_orange_cone' is not in the class map"),
    Case("darknet-missing-label", "yolo", _with(S.darknet, lambda s, p: (s / "a.txt").unlink()),
         r"a.jpg: its YOLO label file .*a.txt is missing \(in the darknet layout"),
    Case("darknet-two-images-one-label", "yolo", _with(S.darknet, lambda s, p: S.image(s / "a.png")),
         r"a.jpg and .*a.png share the label file .*a.txt, which describes one image"),
    Case("yolo-two-images-one-label", "yolo", _yolo(lambda s, p: S.image(s / "images" / "f0.jpg")),
         r"images/f0.jpg and .*images/f0.png share the label file .*labels/f0.txt"),
    Case("coco-size-disagrees", "coco", _with(S.coco, lambda s, p: (s / "instances.json").write_text(
        (s / "instances.json").read_text().replace('"width": 80', '"width": 81'))),
         r"f1.png is 80x60 but its labels state 81x60"),
    Case("coco-unhashable-id", "coco", _with(S.coco, lambda s, p: (s / "instances.json").write_text(
        (s / "instances.json").read_text().replace('{"id": 1, "name"', '{"id": [1], "name"'))),
         r"instances.json: category .* needs an id \(an integer or a string\)"),
    Case("supervisely-objects-not-a-list", "supervisely", _with(S.supervisely, _sly_edit(lambda d: d.update(objects=3))),
         r"x.jpg.json: expected an object with 'size' and an 'objects' list"),
    Case("yolo-image-is-a-pipe", "yolo", _yolo(lambda s, p: (os.mkfifo(s / "images" / "f2.png"), (s / "labels" / "f2.txt").write_text(""))),
         r"images/f2.png is not a regular file"),
    Case("yolo-grey-frame", "yolo", _yolo(lambda s, p: cv2.imwrite(str(s / "images" / "f1.png"), np.zeros((20, 20), np.uint8))),
         r"images/f1.png has 1 channel\(s\); expected colour"),
    Case("source-is-a-file", "yolo", lambda s, t: (s.parent.mkdir(exist_ok=True), s.write_text("x"), [])[2],
         r"source folder .*src is not a folder"),
    # ---- options that need one camera size, and the resume/overwrite pair
    Case("mixed-sizes-with-intrinsics", "yolo",
         lambda s, t: (S.yolo(s, ((S.W, S.H), (80, 60))), ["--intrinsics", "150,150,80,60"])[1],
         r"--intrinsics are of one camera at one size, but the frames have 2 sizes"),
    Case("resume-and-overwrite", "yolo", _yolo(lambda s, p: ["--resume", "--overwrite"]),
         r"--resume continues an interrupted import, --overwrite starts again"),
]


def _snapshot(root: Path) -> dict[str, tuple]:
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            out[str(p.relative_to(root))] = (("link", os.readlink(p)) if p.is_symlink() else
                                             ("file", hashlib.sha1(p.read_bytes()).hexdigest()) if p.is_file()
                                             else ("dir",))
    return out


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_import_bad_input_is_a_typed_error_naming_the_culprit(case, tmp_path, capsys):
    src = tmp_path / "src"
    extra = case.build(src, tmp_path)
    before = _snapshot(tmp_path)
    out = tmp_path / "out"
    assert main(["dataset", "import", case.fmt, str(src), "--out", str(out), "--quiet", *extra]) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.startswith("error: ") and "Traceback" not in err, err
    assert re.search(case.culprit, err), err
    assert S.SECRET not in err + captured.out
    assert _snapshot(tmp_path) == before  # the source unchanged, nothing written anywhere (no --out left)
