"""``dataset import`` of real datasets as they come: frames of several sizes, the darknet layout, Supervisely
(FSOCO) projects, relative and linked source paths, interrupted imports (resume / overwrite) and the lock."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _import_sources as S  # noqa: E402

from weather_gym.cli import main  # noqa: E402
from weather_gym.core._lock import exclusive_folder  # noqa: E402
from weather_gym.core.errors import InputError, OutputExistsError  # noqa: E402
from weather_gym.lab.datasets import importers  # noqa: E402
from weather_gym.lab.datasets.coco import load_coco  # noqa: E402
from weather_gym.lab.datasets.importers import PARTIAL, import_dataset  # noqa: E402


def test_darknet_layout_labels_beside_images_and_a_label_without_an_image(tmp_path, capsys):
    src = S.darknet(tmp_path / "dk")
    assert main(["dataset", "import", "yolo", str(src), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    cap = capsys.readouterr()
    assert "labels beside the images (darknet)" in cap.out
    assert "warning: 1 label file(s) without an image were left out" in cap.err and "c.txt" in cap.err
    ds = load_coco(tmp_path / "out")
    assert [r["file_name"] for r in ds.images] == ["images/a.jpg", "images/sub/b.png"]
    assert [(r["width"], r["height"]) for r in ds.images] == [(S.W, S.H), (80, 60)]
    assert ds.info["labels_without_image"] == ["c.txt"]
    g = ds.gt(1)  # obj.names: 1 = yellow_cone, 2 = unknown_cone (an ignore region)
    np.testing.assert_allclose(g["boxes"][0], [32, 15, 48, 45])
    assert g["classes"][0] == 1 and g["ignore"].tolist() == [False, True]


def test_supervisely_project_boxes_kept_other_geometries_counted(tmp_path):
    src = S.supervisely(tmp_path / "fsoco")
    r = import_dataset("supervisely", src, tmp_path / "out")
    assert r["rows_left_out"] == {"objects of geometry polygon (not a box): left out": 1}
    assert r["labels_without_image"] == ["team_b/ann/gone.png.json"]
    assert r["size"] is None and r["sizes"] == {"80x60": 1, "160x120": 1}
    ds = load_coco(tmp_path / "out")
    assert [im["file_name"] for im in ds.images] == ["images/team_a/x.jpg", "images/team_b/y.png"]
    assert ds.images[0]["source_file"] == "team_a/img/x.jpg"
    g = ds.gt(0)
    np.testing.assert_allclose(g["boxes"], [[10, 20, 40, 80], [60, 20, 70, 40]])
    assert g["classes"][0] == 0 and g["ignore"].tolist() == [False, True]  # unknown_cone: an ignore region
    g = ds.gt(1)  # exterior corners in any order; large_orange_cone -> big_orange
    np.testing.assert_allclose(g["boxes"], [[20, 5, 50, 30]])
    assert g["classes"].tolist() == [3]
    assert (tmp_path / "out" / "images" / "team_a" / "x.jpg").read_bytes() == (
        src / "team_a" / "img" / "x.jpg").read_bytes()


def test_mixed_sizes_import_and_what_the_consumers_need(tmp_path, capsys):
    src = S.yolo(tmp_path / "y", ((S.W, S.H), (80, 60), (S.W, S.H)))
    assert main(["dataset", "import", "yolo", str(src), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert "sizes 80x60 (1), 160x120 (2)" in capsys.readouterr().out
    ds = load_coco(tmp_path / "out")
    assert [(r["width"], r["height"]) for r in ds.images] == [(160, 120), (80, 60), (160, 120)]
    per = ds.info["too_small"]["per_size"]
    assert per["80x60"] == pytest.approx(per["160x120"] / 2)  # the rule at each frame's own scale (letterbox)
    assert main(["dataset", "info", str(tmp_path / "out")]) == 0
    assert "80x60 (1)" in capsys.readouterr().out
    # the gap workflow and a dataset-wide mask need one size, and say so
    from weather_gym.lab.datasets.masks import set_dataset_mask
    from weather_gym.lab.gap.simulate import load_frames

    with pytest.raises(InputError, match="the gap workflow needs one camera resolution"):
        load_frames(ds)
    mask = tmp_path / "m.png"
    S.image(mask)
    with pytest.raises(InputError, match="a dataset-wide mask needs one size"):
        set_dataset_mask(tmp_path / "out", mask)


def test_detector_eval_scores_a_mixed_size_import_end_to_end(tmp_path, capsys):
    src = S.yolo(tmp_path / "y", ((S.W, S.H), (96, 64)))
    out = tmp_path / "ds"
    assert main(["dataset", "import", "yolo", str(src), "--out", str(out), "--quiet"]) == 0
    assert main(["detector", "eval", str(out), "--json", str(tmp_path / "scores.json")]) == 0
    scores = json.loads((tmp_path / "scores.json").read_text())
    assert scores["n_images"] == 2 and scores["n_gt"] == 4
    assert "stored" in scores["too_small"]  # several sizes: the per-frame flags of the import


@pytest.mark.parametrize("how", ["relative", "dot", "through-a-link"])
def test_coco_import_from_a_relative_or_linked_source(how, tmp_path, monkeypatch, capsys):
    src = S.coco(tmp_path / "coco")
    if how == "relative":
        monkeypatch.chdir(tmp_path)
        arg, out = "coco", "out"
    elif how == "dot":
        monkeypatch.chdir(src)
        arg, out = ".", "../out"
    else:
        os.symlink(src, tmp_path / "link")
        arg, out = str(tmp_path / "link"), str(tmp_path / "out")
    assert main(["dataset", "import", "coco", arg, "--out", out, "--quiet"]) == 0, capsys.readouterr().err
    ds = load_coco(tmp_path / "out")
    assert [r["source_file"] for r in ds.images] == ["images/f0.png", "images/f1.png"]
    assert ds.info["source"] == str(src.resolve())


def test_links_that_stay_inside_the_source_are_followed(tmp_path):
    src = S.yolo(tmp_path / "y")
    os.symlink("f0.png", src / "images" / "f2.png")  # the same frame twice, linked inside
    os.symlink("f0.txt", src / "labels" / "f2.txt")
    assert import_dataset("yolo", src, tmp_path / "out")["frames"] == 3


def _interrupt_after(monkeypatch, n: int) -> None:
    real = importers.atomic_write
    count = {"n": 0}

    def write(path, data, **kw):
        if Path(path).parent.name == "images":
            if count["n"] == n:
                raise KeyboardInterrupt
            count["n"] += 1
        return real(path, data, **kw)

    monkeypatch.setattr(importers, "atomic_write", write)


def test_an_interrupted_import_is_resumed_or_replaced(tmp_path, monkeypatch, capsys):
    src = S.yolo(tmp_path / "y", ((S.W, S.H),) * 3)
    out = tmp_path / "out"
    with monkeypatch.context() as m:
        _interrupt_after(m, 1)
        with pytest.raises(KeyboardInterrupt):
            import_dataset("yolo", src, out)
    assert (out / PARTIAL).is_file() and not (out / "annotations.json").exists()
    argv = ["dataset", "import", "yolo", str(src), "--out", str(out), "--quiet"]
    assert main(argv) == 2
    assert "holds an interrupted import" in capsys.readouterr().err
    assert main([*argv, "--resume", "--classes", "blue_cone=blue,yellow_cone=orange"]) == 2  # other settings
    assert "made with other settings (classes" in capsys.readouterr().err
    assert main([*argv, "--resume"]) == 0
    assert "resumed: 1 frames were already copied" in capsys.readouterr().out
    assert len(load_coco(out)) == 3 and not (out / PARTIAL).exists()
    assert main([*argv, "--resume"]) == 2  # nothing left to resume
    assert "is complete" in capsys.readouterr().err
    # interrupted again, then replaced with --overwrite (another source: nothing of the first is left)
    other = S.yolo(tmp_path / "y2", ((80, 60),))
    with monkeypatch.context() as m:
        _interrupt_after(m, 0)
        with pytest.raises(KeyboardInterrupt):
            import_dataset("yolo", other, out, overwrite=True)
    assert (out / PARTIAL).is_file() and not (out / "annotations.json").exists()
    assert main(["dataset", "import", "yolo", str(other), "--out", str(out), "--quiet", "--overwrite"]) == 0
    assert sorted(p.name for p in (out / "images").iterdir()) == ["f0.png"]
    assert [(r["width"], r["height"]) for r in load_coco(out).images] == [(80, 60)]


def test_resume_refuses_a_changed_source(tmp_path, monkeypatch):
    src = S.yolo(tmp_path / "y")
    out = tmp_path / "out"
    with monkeypatch.context() as m:
        _interrupt_after(m, 1)
        with pytest.raises(KeyboardInterrupt):
            import_dataset("yolo", src, out)
    S.image(src / "images" / "f1.png", value=200)
    os.utime(src / "images" / "f1.png", ns=(1, 1))
    with pytest.raises(InputError, match="the source files changed since"):
        import_dataset("yolo", src, out, resume=True)


def test_a_folder_left_by_an_older_interrupted_import_can_be_replaced(tmp_path):
    src = S.yolo(tmp_path / "y")
    out = tmp_path / "out"
    S.image(out / "images" / "old.png")  # frames copied, no annotations.json, no marker
    with pytest.raises(OutputExistsError, match="is not empty"):
        import_dataset("yolo", src, out)
    import_dataset("yolo", src, out, overwrite=True)
    assert sorted(p.name for p in (out / "images").iterdir()) == ["f0.png", "f1.png"]


def test_a_second_import_into_the_same_out_is_refused_up_front(tmp_path, capsys):
    src = S.yolo(tmp_path / "y")
    out = tmp_path / "out"
    out.mkdir()
    with exclusive_folder(out, busy="held by the test"):  # what a running import holds
        assert main(["dataset", "import", "yolo", str(src), "--out", str(out), "--quiet"]) == 2
        assert "another import is writing into" in capsys.readouterr().err
        assert not any(out.iterdir())
    assert main(["dataset", "import", "yolo", str(src), "--out", str(out), "--quiet"]) == 0  # released


def test_a_dataset_whose_annotations_json_links_out_is_refused(tmp_path):
    """The same confinement for a dataset folder another command reads (``load_coco``)."""
    from weather_gym.core.errors import OutsideRootError

    import_dataset("yolo", S.yolo(tmp_path / "y"), tmp_path / "real")
    ds = tmp_path / "ds"
    (ds / "images").mkdir(parents=True)
    os.symlink(tmp_path / "real" / "annotations.json", ds / "annotations.json")
    with pytest.raises(OutsideRootError, match=r"ds/annotations.json is a symbolic link"):
        load_coco(ds)


def test_a_frame_turned_by_its_exif_orientation_is_recorded_as_it_is_read(tmp_path):
    """A JPEG whose EXIF says "turned 90 degrees": recorded at the size every reader decodes (and labelling
    tools show), so the boxes and the frame agree."""
    from PIL import Image

    src = tmp_path / "y"
    (src / "images").mkdir(parents=True)
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.new("RGB", (S.W, S.H), (90, 90, 90)).save(src / "images" / "f0.jpg", exif=exif)
    (src / "labels").mkdir()
    (src / "labels" / "f0.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    import_dataset("yolo", src, tmp_path / "out", classes="0=blue")
    ds = load_coco(tmp_path / "out")
    assert (ds.images[0]["width"], ds.images[0]["height"]) == (S.H, S.W)
    assert ds.image(0).shape == (S.W, S.H, 3)
