"""``weather-gym dataset import``: KITTI, YOLO and COCO sources into the project's COCO layout."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from weather_gym.cli import main
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.importers import import_dataset
from weather_gym.perception.labels import SmallRule

W, H = 160, 120


def _image(path, w=W, h=H, value=90):
    path.parent.mkdir(parents=True, exist_ok=True)
    img = np.full((h, w, 3), value, np.uint8)
    img[10:30, 10:20] = (200, 40, 40)
    assert cv2.imwrite(str(path), img)
    return path


def _kitti_row(cls, box, loc=(0.0, 0.0, 0.0)):
    x1, y1, x2, y2 = box
    dims = "0.36 0.25 0.25" if any(loc) else "0.00 0.00 0.00"
    return f"{cls} 0.00 0 0.00 {x1:.2f} {y1:.2f} {x2:.2f} {y2:.2f} {dims} {loc[0]} {loc[1]} {loc[2]} 0.00"


@pytest.fixture
def kitti_src(tmp_path):
    """Two frames; vehicle-frame 3D locations (x forward, y left), one 3D-only row, one unknown cone."""
    src = tmp_path / "kitti"
    for stem in ("000001", "000002"):
        _image(src / "images" / f"{stem}.png")
    rows = [
        _kitti_row("blue_cone", (10, 40, 30, 80), (4.0, 2.0, -0.9)),       # left of the image, y > 0 (left)
        _kitti_row("yellow_cone", (120, 40, 140, 80), (4.0, -2.0, -0.9)),  # right
        _kitti_row("blue_cone", (20, 50, 28, 62), (9.0, 3.0, -0.9)),       # 12 px tall
        _kitti_row("unknown_cone", (60, 50, 70, 70)),
        _kitti_row("blue_cone", (0, 0, 0, 0), (12.0, 3.0, -0.9)),          # 3D only
        _kitti_row("yellow_cone", (100, 40, 115, 70), (5.0, -1.5, -0.9)),
        _kitti_row("blue_cone", (30, 45, 45, 75), (5.0, 1.5, -0.9)),
    ]
    (src / "labels").mkdir()
    (src / "labels" / "000001.txt").write_text("\n".join(rows) + "\n")
    (src / "labels" / "000002.txt").write_text(rows[1] + "\n")
    return src


def test_kitti_import_records_boxes_ignore_regions_and_intrinsics(kitti_src, tmp_path):
    out = tmp_path / "out"
    r = import_dataset("kitti", kitti_src, out, intrinsics="150,149,70.5,62", condition="droplets", severity=3)
    assert r["frames"] == 2 and r["rows_left_out"] == {"rows without a 2D box (3D only): left out": 1}
    ds = load_coco(out)
    rec = ds.record(0)
    assert rec["width"] == W and rec["height"] == H and rec["source_file"] == "images/000001.png"
    assert rec["intrinsics"] == {"fx": 150.0, "fy": 149.0, "cx": 70.5, "cy": 62.0}
    cam = ds.camera(0)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == pytest.approx((150.0, 149.0, 70.5, 62.0))
    assert rec["condition"] == "droplets" and rec["severity"] == 3
    # the frame is copied byte for byte
    assert (out / rec["file_name"]).read_bytes() == (kitti_src / "images" / "000001.png").read_bytes()
    g = ds.gt(0)
    assert len(g["boxes"]) == 6  # the 3D-only row is left out, not a miss
    unknown = int(np.flatnonzero(g["ignore"])[0])
    assert g["any_class"][unknown] and g["iscrowd"][unknown] == 1
    # too small at the detector's input scale, not at a fixed pixel count
    rule = SmallRule.for_image((W, H))
    heights = g["boxes"][:, 3] - g["boxes"][:, 1]
    assert (g["iscrowd"].astype(bool) & ~g["ignore"]).tolist() == (heights < rule.min_height_px).tolist()
    info = json.loads((out / "annotations.json").read_text())["info"]
    assert info["too_small"]["min_input_px"] == pytest.approx(8 * 512 / 672)
    assert info["too_small"]["rule"] == rule.describe()
    # range from the 3D location (recognised as the vehicle frame)
    assert r["location_frame"].startswith("vehicle")
    assert g["ranges"][0] == pytest.approx(math.hypot(4.0, 2.0), rel=1e-5)
    assert g["bearings"][0] == pytest.approx(math.atan2(2.0, 4.0), rel=1e-5)


def test_kitti_calib_files_give_the_intrinsics(kitti_src, tmp_path):
    (kitti_src / "calib").mkdir()
    for stem in ("000001", "000002"):
        (kitti_src / "calib" / f"{stem}.txt").write_text(
            "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nP2: 140.0 0 75.0 0 0 141.0 58.0 0 0 0 1 0\n")
    import_dataset("kitti", kitti_src, tmp_path / "out")
    assert load_coco(tmp_path / "out").record(1)["intrinsics"] == {"fx": 140.0, "fy": 141.0, "cx": 75.0, "cy": 58.0}


def test_yolo_import_with_class_names_and_a_frame_without_cones(tmp_path):
    src = tmp_path / "yolo"
    _image(src / "images" / "a.jpg")
    _image(src / "images" / "b.jpg")
    (src / "labels").mkdir()
    (src / "labels" / "a.txt").write_text("0 0.25 0.5 0.1 0.5\n1 0.75 0.5 0.1 0.5\n2 0.5 0.5 0.05 0.1\n")
    (src / "labels" / "b.txt").write_text("")
    (src / "data.yaml").write_text("path: .\nnames:\n  0: blue_cone\n  1: yellow_cone\n  2: unknown_cone\n")
    import_dataset("yolo", src, tmp_path / "out")
    ds = load_coco(tmp_path / "out")
    g = ds.gt(0)
    np.testing.assert_allclose(g["boxes"][0], [32, 30, 48, 90])
    assert g["classes"][:2].tolist() == [0, 1] and g["ignore"].tolist() == [False, False, True]
    assert len(ds.gt(1)["boxes"]) == 0
    # by index, without a names file
    (src / "data.yaml").unlink()
    import_dataset("yolo", src, tmp_path / "out2", classes="0=blue,1=yellow,2=ignore")
    assert load_coco(tmp_path / "out2").gt(0)["ignore"].tolist() == [False, False, True]


def test_coco_import_maps_category_names_and_keeps_crowds_as_ignore_regions(tmp_path):
    src = tmp_path / "coco"
    _image(src / "images" / "f0.png")
    (src / "instances.json").write_text(json.dumps({
        "images": [{"id": 7, "file_name": "f0.png", "width": W, "height": H}],
        "categories": [{"id": 1, "name": "blue_cone"}, {"id": 2, "name": "large_orange_cone"}],
        "annotations": [{"id": 1, "image_id": 7, "category_id": 2, "bbox": [10, 20, 30, 60], "iscrowd": 0},
                        {"id": 2, "image_id": 7, "category_id": 1, "bbox": [50, 20, 10, 30], "iscrowd": 1}]}))
    import_dataset("coco", src, tmp_path / "out")
    g = load_coco(tmp_path / "out").gt(0)
    assert g["classes"][0] == 3 and g["ignore"].tolist() == [False, True]
    assert not g["any_class"][1]  # a crowd of blue cones ignores blue detections only


@pytest.mark.parametrize("case, match", [
    ("class_left_out", r"labels/000001.txt:4: class 'unknown_cone' is not in the class map"),
    ("missing_label", r"its KITTI label file .*000002.txt is missing"),
    ("bad_row", r"labels/000002.txt:1: a KITTI row has 15 values"),
    ("size", r"--intrinsics are of one camera at one size, but the frames have 2 sizes \(80x60 \(1\), 160x120 \(1\)\)"),
    ("outside", r"lies outside the 160x120 image"),
    ("intrinsics", r"cx must lie in \[0, 160\]"),
    ("format", r"unknown dataset format 'voc'"),
    ("severity", r"needs --severity 1-4"),
])
def test_bad_input_is_a_clear_error_and_writes_nothing(case, match, kitti_src, tmp_path):
    kw = {}
    fmt = "kitti"
    if case == "class_left_out":
        kw["classes"] = "blue_cone=blue,yellow_cone=yellow"
    elif case == "missing_label":
        (kitti_src / "labels" / "000002.txt").unlink()
    elif case == "bad_row":
        (kitti_src / "labels" / "000002.txt").write_text("blue_cone 1 2 3\n")
    elif case == "size":
        _image(kitti_src / "images" / "000002.png", w=80, h=60)
        kw["intrinsics"] = "150,149,70.5,62"
    elif case == "outside":
        (kitti_src / "labels" / "000002.txt").write_text(_kitti_row("blue_cone", (150, 10, 190, 50)) + "\n")
    elif case == "intrinsics":
        kw["intrinsics"] = "150,150,400,60"
    elif case == "format":
        fmt = "voc"
    elif case == "severity":
        kw["condition"] = "droplets"
    out = tmp_path / "out"
    with pytest.raises((ValueError, FileNotFoundError), match=match):
        import_dataset(fmt, kitti_src, out, **kw)
    assert not out.exists() or not any(out.iterdir())


def test_cli_import_refuses_an_existing_dataset_and_writes_only_under_out(kitti_src, tmp_path, capsys):
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert main(["dataset", "import", "kitti", str(kitti_src), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert all(str(p).startswith("out") for p in set(after) - set(before))
    assert "too small" in capsys.readouterr().out
    assert main(["dataset", "import", "kitti", str(kitti_src), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["dataset", "info", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    assert "ignore regions (not misses): unknown_cone 1" in text
    assert SmallRule.for_image((W, H)).describe() in text


@pytest.mark.slow
def test_real_kitti_frames_import(real_frames_src, tmp_path, capsys):
    """The FSKITTI frames: 3D-only rows left out, the too-small rule at the detector's scale, intrinsics."""
    out = tmp_path / "real"
    assert main(["dataset", "import", "kitti", str(real_frames_src), "--out", str(out), "--quiet",
                 "--intrinsics", "900.9,900.1,506.4,358.0", "--condition", "clear"]) == 0
    text = capsys.readouterr().out
    assert "imported 23 frames (1024x768)" in text
    assert "rows without a 2D box (3D only): left out: 497" in text
    assert "box height < 16.3 px (6.1 px at the detector's 512x288 input, letterbox x0.375)" in text
    ds = load_coco(out)
    assert ds.record(0)["intrinsics"]["cx"] == 506.4 and ds.camera(0).cy == 358.0
    assert ds.info["location_frame"].startswith("vehicle")
    ranges = np.concatenate([ds.gt(i)["ranges"] for i in range(len(ds))])
    assert np.isfinite(ranges).sum() == 188 and 2.0 < np.nanmedian(ranges) < 40.0  # boxes with a 3D location


def _pitched_box(loc, fx=300.0, cx=320.0, cy=240.0, pitch_deg=12.0, h=0.36, w=0.25):
    """The 2D box of a cone at vehicle-frame ``loc`` (x forward, y left, z up; bottom centre) seen by a camera
    pitched down by ``pitch_deg`` (an independent pinhole, not the importer's code)."""
    t = math.radians(pitch_deg)

    def px(x, y, z):
        r, d0, f0 = -y, -z, x
        d, f = d0 * math.cos(t) - f0 * math.sin(t), d0 * math.sin(t) + f0 * math.cos(t)
        return fx * r / f + cx, fx * d / f + cy, f

    ub, vb, f = px(*loc)
    _, vt, _ = px(loc[0], loc[1], loc[2] + h)
    half = fx * w / 2 / f
    return ub - half, vt, ub + half, vb


def test_3d_only_kitti_cones_become_ignore_regions_where_the_fitted_camera_sees_them(tmp_path):
    """A pitched camera (as on a race car): the pose is fitted to the rows with both boxes, and each
    3D-only cone in view becomes an ignore region over its true box; repeats and cones behind are skipped."""
    src = tmp_path / "kitti"
    _image(src / "images" / "000001.png", 640, 480)
    both = [(x, y, -1.0) for x in (4.0, 6.0, 9.0, 13.0) for y in (-2.0, 2.0)]
    rows = [_kitti_row("blue_cone" if loc[1] > 0 else "yellow_cone", _pitched_box(loc), loc) for loc in both]
    only = [(7.5, 1.0, -1.0), (11.0, -3.0, -1.0)]
    rows += [_kitti_row("blue_cone", (0, 0, 0, 0), loc) for loc in only]
    rows.append(_kitti_row("blue_cone", (0, 0, 0, 0), both[0]))  # the same cone again, 3D only
    rows.append(_kitti_row("blue_cone", (0, 0, 0, 0), (-5.0, 1.0, -1.0)))  # behind the car
    (src / "labels").mkdir()
    (src / "labels" / "000001.txt").write_text("\n".join(rows) + "\n")
    r = import_dataset("kitti", src, tmp_path / "out", intrinsics="300,300,320,240")
    assert r["rows_left_out"] == {"rows without a 2D box (3D only): left out": 4}
    assert r["projected_3d"].startswith("2 3D-only cones in view projected into ignore regions (1 behind or out of "
                                        "the frame, 1 repeating a cone with a 2D box)")
    gt = load_coco(tmp_path / "out").gt(0)
    regions = gt["boxes"][gt["ignore"] & gt["any_class"]]
    assert len(regions) == 2 and gt["iscrowd"][gt["ignore"]].all()
    for loc, region in zip(only, regions, strict=True):
        true = np.array(_pitched_box(loc))
        assert (region[:2] <= true[:2] + 1).all() and (region[2:] >= true[2:] - 1).all()  # covers the cone
        assert (region[2] - region[0]) < 2.5 * (true[2] - true[0])  # and not much more


def test_3d_only_cones_are_left_out_when_too_few_rows_fix_the_camera(kitti_src, tmp_path):
    r = import_dataset("kitti", kitti_src, tmp_path / "out", intrinsics="150,149,70.5,62")
    assert r["projected_3d"] is None
    anns = load_coco(tmp_path / "out").annotations(0)
    assert [a["source_class"] for a in anns if a.get("ignore")] == ["unknown_cone"]  # no projected region
