"""Small synthetic import sources (a few tiny frames, made here) for the ``dataset import`` tests."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

W, H = 160, 120
SECRET = "PRIVATE-LINE-do-not-copy"


def image(path: Path, w: int = W, h: int = H, value: int = 90) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    img = np.full((h, w, 3), value, np.uint8)
    img[10:30, 10:20] = (200, 40, 40)
    assert cv2.imwrite(str(path), img)
    return path


def private(tmp: Path) -> Path:
    """A folder outside every source, with a private text file and a private image."""
    d = tmp / "private"
    d.mkdir(exist_ok=True)
    (d / "secret.txt").write_text(f"{SECRET}\n0 0.5 0.5 0.1 0.1\n")
    image(d / "secret.png", value=7)
    return d


def yolo(src: Path, sizes: tuple[tuple[int, int], ...] = ((W, H), (W, H))) -> Path:
    """images/ + labels/, classes.txt; one frame per size."""
    for i, (w, h) in enumerate(sizes):
        image(src / "images" / f"f{i}.png", w, h)
        (src / "labels").mkdir(parents=True, exist_ok=True)
        (src / "labels" / f"f{i}.txt").write_text("0 0.25 0.5 0.1 0.5\n1 0.75 0.5 0.1 0.5\n")
    (src / "classes.txt").write_text("blue_cone\nyellow_cone\n")
    return src


def darknet(src: Path) -> Path:
    """``img.jpg`` + ``img.txt`` side by side (also in a sub-folder), ``obj.names``, a list file, an orphan
    label and macOS archive leftovers."""
    image(src / "a.jpg")
    (src / "a.txt").write_text("0 0.25 0.5 0.1 0.5\n")
    image(src / "sub" / "b.png", 80, 60)
    (src / "sub" / "b.txt").write_text("1 0.5 0.5 0.2 0.5\n2 0.5 0.5 0.05 0.1\n")
    (src / "obj.names").write_text("blue_cone\nyellow_cone\nunknown_cone\n")
    (src / "train.txt").write_text("a.jpg\nsub/b.png\n")
    (src / "c.txt").write_text("0 0.5 0.5 0.1 0.1\n")  # a label without an image
    (src / "__MACOSX").mkdir()
    (src / "__MACOSX" / "._a.jpg").write_bytes(b"\x00\x05\x16\x07")  # an archive's resource fork: skipped
    (src / "._a.jpg").write_bytes(b"\x00\x05\x16\x07")
    return src


def coco(src: Path) -> Path:
    image(src / "images" / "f0.png")
    image(src / "images" / "f1.png", 80, 60)
    (src / "instances.json").write_text(json.dumps({
        "images": [{"id": 1, "file_name": "f0.png", "width": W, "height": H},
                   {"id": 2, "file_name": "f1.png", "width": 80, "height": 60}],
        "categories": [{"id": 1, "name": "blue_cone"}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [10, 20, 30, 60]},
                        {"id": 2, "image_id": 2, "category_id": 1, "bbox": [10, 10, 20, 40]}]}))
    return src


def rectangle(cls: str, x1: float, y1: float, x2: float, y2: float) -> dict:
    return {"id": 1, "classTitle": cls, "geometryType": "rectangle", "tags": [],
            "points": {"exterior": [[x1, y1], [x2, y2]], "interior": []}}


def supervisely(src: Path) -> Path:
    """A Supervisely project like FSOCO: meta.json, two datasets (teams) of frames of two sizes."""
    src.mkdir(parents=True, exist_ok=True)
    titles = ("blue_cone", "yellow_cone", "orange_cone", "large_orange_cone", "unknown_cone")
    (src / "meta.json").write_text(json.dumps({
        "classes": [{"title": t, "shape": "rectangle", "color": "#0000FF"} for t in titles], "tags": []}))
    image(src / "team_a" / "img" / "x.jpg")
    (src / "team_a" / "ann").mkdir(parents=True)
    (src / "team_a" / "ann" / "x.jpg.json").write_text(json.dumps({
        "description": "", "tags": [], "size": {"height": H, "width": W},
        "objects": [rectangle("blue_cone", 10, 20, 40, 80), rectangle("unknown_cone", 60, 20, 70, 40),
                    {"id": 3, "classTitle": "yellow_cone", "geometryType": "polygon",
                     "points": {"exterior": [[1, 1], [5, 1], [3, 6]], "interior": []}}]}))
    image(src / "team_b" / "img" / "y.png", 80, 60)
    (src / "team_b" / "ann").mkdir(parents=True)
    (src / "team_b" / "ann" / "y.png.json").write_text(json.dumps({
        "size": {"height": 60, "width": 80}, "objects": [rectangle("large_orange_cone", 50, 30, 20, 5)]}))
    (src / "team_b" / "ann" / "gone.png.json").write_text(json.dumps({"size": {"height": 60, "width": 80},
                                                                      "objects": []}))
    return src
