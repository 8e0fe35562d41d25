"""COCO dataset writing and validated reading (no simulator needed)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from weather_gym.core.errors import FileFormatError
from weather_gym.lab.datasets.coco import CocoWriter, load_coco, read_depth_png, write_depth_png
from weather_gym.perception.labels import MIN_BOX_HEIGHT_PX

GT = {"boxes": np.array([[10, 20, 30, 60], [100, 100, 104, 105.]]), "classes": np.array([1, 3]),
      "ranges": np.array([5.0, 30.0]), "bearings": np.array([0.1, -0.2]), "cone_ids": np.array([4, 9]),
      "pixels": np.array([500, 12])}


def _write(root, n=2, **kw):
    img = np.zeros((50, 80, 3), np.uint8)
    img[5:10, 5:10] = (255, 0, 0)
    with CocoWriter(root, **kw) as w:
        for _i in range(n):
            w.add(img, {"track": "t", "pose": [1.0, 2.0, 0.5], "speed": 3.0}, GT,
                  depth=np.full((50, 80), 7.25, np.float32))
    return root


def test_round_trip_keeps_images_depth_and_annotations(tmp_path):
    ds = load_coco(_write(tmp_path / "d"))
    assert len(ds) == 2
    img = ds.image(0)
    assert img.shape == (50, 80, 3) and tuple(img[6, 6]) == (255, 0, 0)  # RGB order preserved
    np.testing.assert_allclose(ds.depth(0), 7.25)
    g = ds.gt(1)
    np.testing.assert_allclose(g["boxes"], GT["boxes"])
    assert g["classes"].tolist() == [1, 3] and g["cone_ids"].tolist() == [4, 9]
    assert g["iscrowd"].tolist() == [0, 1]  # 5 px tall < MIN_BOX_HEIGHT_PX
    rec = ds.record(0)
    assert rec["track"] == "t" and rec["pose"] == [1.0, 2.0, 0.5] and rec["depth_file"] == "depth/000000.png"
    data = json.loads((tmp_path / "d" / "annotations.json").read_text())
    assert [c["name"] for c in data["categories"]] == ["blue", "yellow", "orange", "big_orange"]
    a = data["annotations"][0]
    assert a["category_id"] == 2 and a["bbox"] == [10.0, 20.0, 20.0, 40.0] and a["area"] == 800.0
    assert a["range"] == 5.0 and a["pixels"] == 500
    assert data["info"]["min_box_height_px"] == MIN_BOX_HEIGHT_PX


def test_depth_png_is_millimetres_and_saturates(tmp_path):
    d = np.array([[0.0, 1.2345, 65.535, 80.0]], np.float32)
    write_depth_png(tmp_path / "d.png", d)
    np.testing.assert_allclose(read_depth_png(tmp_path / "d.png"), [[0.0, 1.234, 65.535, 65.535]], atol=1e-3)


def test_existing_dataset_is_never_overwritten(tmp_path):
    root = _write(tmp_path / "d")
    with pytest.raises(FileExistsError, match="annotations.json"):
        CocoWriter(root)
    _write(root, n=1, overwrite=True)
    assert len(load_coco(root)) == 1


def test_interrupted_writer_resumes(tmp_path):
    root = tmp_path / "d"
    img = np.zeros((20, 20, 3), np.uint8)
    w = CocoWriter(root)
    w.add(img, {}, GT)
    w.abort()  # as after a crash: the journal stays, no annotations.json
    with pytest.raises(FileNotFoundError, match="--resume"):
        load_coco(root)
    with pytest.raises(FileExistsError, match="--resume"):
        CocoWriter(root)
    w2 = CocoWriter(root, resume=True)
    assert w2.done == 1
    w2.add(img, {}, GT)
    w2.close()
    ds = load_coco(root)
    assert len(ds) == 2 and [a["id"] for a in ds.data["annotations"]] == [1, 2, 3, 4]


def test_missing_folder_and_annotations_name_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere"):
        load_coco(tmp_path / "nothere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match=r"empty/annotations\.json"):
        load_coco(tmp_path / "empty")


def test_annotations_pointing_to_missing_image_name_it(tmp_path):
    root = _write(tmp_path / "d")
    (root / "images" / "000001.png").unlink()
    with pytest.raises(FileNotFoundError, match=r"images/000001\.png"):
        load_coco(root)


def test_empty_image_file_is_named(tmp_path):
    root = _write(tmp_path / "d")
    (root / "images" / "000000.png").write_bytes(b"")
    with pytest.raises(ValueError, match=r"000000\.png.*empty"):
        load_coco(root)
    (root / "images" / "000000.png").write_bytes(b"garbage")
    ds = load_coco(root)
    with pytest.raises(ValueError, match=r"000000\.png.*decoded"):
        ds.image(0)


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d.pop("annotations"), "annotations"),
    (lambda d: d["annotations"][0].update(bbox=[1, 2, -3, 4]), "bbox"),
    (lambda d: d["annotations"][0].update(image_id=99), "image_id"),
    (lambda d: d["annotations"][0].update(category_id=9), "category_id"),
    (lambda d: d["categories"].append({"id": 9, "name": "green"}), "green"),
    (lambda d: d["images"][0].pop("file_name"), "file_name"),
])
def test_malformed_annotations_are_named(tmp_path, mutate, match):
    root = _write(tmp_path / "d")
    path = root / "annotations.json"
    data = json.loads(path.read_text())
    mutate(data)
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=match):
        load_coco(root)


def test_invalid_json_is_named(tmp_path):
    root = _write(tmp_path / "d")
    (root / "annotations.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"annotations\.json is not valid JSON"):
        load_coco(root)


def test_one_writer_per_dataset_folder(tmp_path):
    from weather_gym.core.errors import OutputExistsError

    first = CocoWriter(tmp_path / "d")
    try:
        with pytest.raises(OutputExistsError, match="another run is writing the dataset"):
            CocoWriter(tmp_path / "d", resume=True)
    finally:
        first.abort()
    _write(tmp_path / "d", resume=True)  # released: a resumed run gets the folder


def test_a_resume_with_other_settings_is_refused_naming_them(tmp_path):
    from weather_gym.core.errors import InputError

    img = np.zeros((50, 80, 3), np.uint8)
    w = CocoWriter(tmp_path / "d", identity={"seed": 5, "frames": 4})
    w.add(img, {"track": "t"}, GT)
    w.abort()  # interrupted after one frame
    with pytest.raises(InputError, match=r"--resume: .*\(seed\): seed: 5 there, 6 now"):
        CocoWriter(tmp_path / "d", resume=True, identity={"seed": 6, "frames": 4})
    w = CocoWriter(tmp_path / "d", resume=True, identity={"seed": 5, "frames": 4})
    assert w.done == 1
    w.add(img, {"track": "t"}, GT)
    w.close()
    assert len(load_coco(tmp_path / "d")) == 2


@pytest.mark.parametrize("cache", [False, True])
def test_a_record_whose_size_disagrees_with_its_image_is_refused(tmp_path, cache):
    root = _write(tmp_path / "d", n=1)
    data = json.loads((root / "annotations.json").read_text())
    data["images"][0]["width"] = 81  # the file is 80 wide
    (root / "annotations.json").write_text(json.dumps(data))
    ds = load_coco(root, cache_images=cache)
    with pytest.raises(FileFormatError, match=r"annotations.json: image 0 is 81x50 .* its file .*000000.png is 80x50"):
        ds.image(0)
