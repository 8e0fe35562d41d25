"""Pooling COCO datasets: frames, labels and ignore masks survive the merge; bad input is refused clearly."""

import json

import numpy as np
import pytest

from weather_gym.cli import main
from weather_gym.core.errors import InputError, OutputExistsError, OutputPathError
from weather_gym.lab.datasets.coco import CocoWriter, load_coco
from weather_gym.lab.datasets.masks import set_dataset_mask, write_mask
from weather_gym.lab.datasets.merge import merge_coco

H, W = 60, 80


def _dataset(root, n, shade, min_box_height=8.0):
    with CocoWriter(root, min_box_height=min_box_height) as w:
        for i in range(n):
            img = np.full((H, W, 3), shade + i, np.uint8)
            w.add(img, {"track": f"t{shade}"}, {"boxes": np.array([[5.0 + i, 5, 15 + i, 30], [40, 10, 50, 40]]),
                                                "classes": np.array([0, 1])},
                  depth=np.full((H, W), 7.0, np.float32))
    return root


def test_merge_keeps_every_frame_its_pixels_labels_and_depth(tmp_path):
    a, b = _dataset(tmp_path / "a", 3, 10), _dataset(tmp_path / "b", 2, 100)
    out = merge_coco([a, b], tmp_path / "ab")
    ds, da, db = load_coco(out), load_coco(a), load_coco(b)
    assert len(ds) == 5 and [s["images"] for s in ds.info["sources"]] == [3, 2]
    assert len({r["id"] for r in ds.images}) == 5 and len({r["file_name"] for r in ds.images}) == 5
    for i, (src, j) in enumerate([(da, 0), (da, 1), (da, 2), (db, 0), (db, 1)]):
        np.testing.assert_array_equal(ds.image(i), src.image(j))
        np.testing.assert_array_equal(ds.gt(i)["boxes"], src.gt(j)["boxes"])
        np.testing.assert_array_equal(ds.gt(i)["classes"], src.gt(j)["classes"])
        assert ds.record(i)["track"] == src.record(j)["track"] and ds.record(i)["source"] == (0 if src is da else 1)
    assert (out / ds.record(4)["depth_file"]).is_file()
    assert ds.info["sources"][1]["path"] == str(b)


def test_a_dataset_wide_ignore_mask_stays_with_its_frames_only(tmp_path):
    a, b = _dataset(tmp_path / "a", 2, 10), _dataset(tmp_path / "b", 2, 100)
    mask = np.zeros((H, W), bool)
    mask[40:] = True
    write_mask(tmp_path / "m.png", mask)
    set_dataset_mask(b, tmp_path / "m.png")
    ds = load_coco(merge_coco([a, b], tmp_path / "ab"))
    assert ds.ignore_mask(0) is None and ds.ignore_mask(1) is None
    np.testing.assert_array_equal(ds.ignore_mask(2), mask)
    np.testing.assert_array_equal(ds.ignore_mask(3), mask)


def test_merge_refuses_what_would_mix_definitions_or_lose_data(tmp_path):
    a, b = _dataset(tmp_path / "a", 1, 10), _dataset(tmp_path / "b", 1, 100)
    c = _dataset(tmp_path / "c", 1, 50, min_box_height=4.0)
    with pytest.raises(InputError, match=r"c: info.min_box_height_px 4 differs from .*a's 8"):
        merge_coco([a, c], tmp_path / "x")
    with pytest.raises(InputError, match="at least two"):
        merge_coco([a], tmp_path / "x")
    with pytest.raises(InputError, match="given twice"):
        merge_coco([a, tmp_path / "b" / ".." / "a"], tmp_path / "x")
    with pytest.raises(OutputPathError, match="lies inside, the source dataset"):
        merge_coco([a, b], a / "pool")
    merge_coco([a, b], tmp_path / "ab")
    before = (tmp_path / "ab" / "annotations.json").read_bytes()
    with pytest.raises(OutputExistsError, match="already exists"):
        merge_coco([a, c.parent / "b"], tmp_path / "ab")
    assert (tmp_path / "ab" / "annotations.json").read_bytes() == before  # nothing a user has is overwritten
    data = json.loads((b / "annotations.json").read_text())
    data["categories"] = [dict(cat, name="orange") if cat["name"] == "blue" else cat for cat in data["categories"]
                          if cat["name"] != "orange"]
    (b / "annotations.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="categories .* differ"):
        merge_coco([a, b], tmp_path / "y")


def test_cli_merges_and_reports(tmp_path, capsys):
    a, b = _dataset(tmp_path / "a", 2, 10), _dataset(tmp_path / "b", 1, 100)
    assert main(["dataset", "merge", str(a), str(b), "--out", str(tmp_path / "ab")]) == 0
    assert "3 frames from 2 datasets (2, 1)" in capsys.readouterr().out
    assert main(["dataset", "merge", str(a), str(b), "--out", str(tmp_path / "ab")]) != 0
    assert "already exists" in capsys.readouterr().err
