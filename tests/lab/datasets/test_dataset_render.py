"""Rendering COCO datasets with the simulator and the ground-truth driver."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.lab.datasets import coco_writer, load_coco, render_dataset
from weather_gym.lab.datasets.render import episode_plan

pytestmark = pytest.mark.slow

KW = dict(tracks=["small_track"], frames=4, seed=3, randomize=True, frames_per_episode=2, progress=False)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    root = tmp_path_factory.mktemp("render") / "a"
    render_dataset(root, **KW)
    return root


def test_records_and_annotations_carry_the_contract_fields(rendered):
    ds = load_coco(rendered)
    assert len(ds) == 4
    rec = ds.record(0)
    for key in ("track", "pose", "speed", "yaw_rate", "camera", "depth_file", "look", "seed"):
        assert key in rec
    assert rec["camera"]["width"] == 672 and len(rec["pose"]) == 3
    assert ds.record(0)["look"] != ds.record(2)["look"]  # a new random look per episode
    anns = [a for i in range(len(ds)) for a in ds.annotations(i)]
    assert anns, "the driver should see cones"
    for a in anns:
        assert {"bbox", "area", "category_id", "iscrowd", "range", "bearing", "cone_id"} <= set(a)
        assert a["iscrowd"] == int(a["bbox"][3] < 8)
    depth = ds.depth(0)
    assert depth.shape == (376, 672) and 0 < float(np.median(depth)) < 80


def test_same_seed_same_bytes_and_interrupted_render_resumes(rendered, tmp_path, monkeypatch):
    class Crash(coco_writer.CocoWriter):
        def add(self, *a, **k):
            if self.done >= 3:
                raise KeyboardInterrupt
            return super().add(*a, **k)

    monkeypatch.setattr(coco_writer, "CocoWriter", Crash)  # render writes through coco_writer.CocoWriter
    with pytest.raises(KeyboardInterrupt):
        render_dataset(tmp_path / "b", **KW)
    monkeypatch.undo()
    with pytest.raises(FileExistsError, match="--resume"):
        render_dataset(tmp_path / "b", **KW)
    render_dataset(tmp_path / "b", resume=True, **KW)
    for i in range(4):
        name = f"{i:06d}.png"
        assert (rendered / "images" / name).read_bytes() == (tmp_path / "b" / "images" / name).read_bytes()
    a, b = load_coco(rendered), load_coco(tmp_path / "b")
    assert a.data["annotations"] == b.data["annotations"] and a.images == b.images


def test_render_view_reproduces_a_frame(rendered):
    ds = load_coco(rendered)
    try:
        view = ds.render_view(1)
    finally:
        ds.close()
    diff = np.abs(view["image"].astype(int) - ds.image(1).astype(int))
    assert diff.mean() < 0.1  # the same scene, camera model and sensor noise (the frame's camera_frame)
    np.testing.assert_allclose(view["gt"]["boxes"], ds.gt(1)["boxes"], atol=1.0)


def test_episode_plan_splits_frames_evenly():
    assert episode_plan(["a", "b"], 5, 2) == [("a", 2), ("a", 1), ("b", 2)]
    with pytest.raises(ValueError, match="frames"):
        episode_plan(["a"], 0, 2)


def test_a_csv_track_travels_with_the_dataset(tmp_path):
    """A cone CSV given as a track is copied into DIR/tracks/ and the records name the copy, so the
    dataset is self-contained and its track paths stay inside it (see datasets.coco.record_path)."""
    from weather_gym.camera.config import CameraConfig
    from weather_gym.tracks import load_track

    csv = tmp_path / "elsewhere" / "my_oval.csv"
    csv.parent.mkdir()
    load_track("oval").to_csv(csv)
    root = tmp_path / "ds"
    render_dataset(root, tracks=[str(csv)], frames=2, frames_per_episode=2, camera=CameraConfig(width=64, height=36),
                   progress=False)
    ds = load_coco(root)
    assert ds.record(0)["track"] == "tracks/my_oval.csv"
    assert (root / "tracks" / "my_oval.csv").read_bytes() == csv.read_bytes()
    csv.unlink()  # the original may go away: the dataset still re-renders its views
    assert ds.track_spec(0) == str((root / "tracks" / "my_oval.csv").resolve())
    view = ds.render_view(0)
    ds.close()
    assert view["image"].shape == (36, 64, 3)


def test_a_reversed_csv_track_travels_with_the_dataset_and_its_merge(tmp_path):
    """``reverse:PATH.csv``: the CSV is copied as above and the records keep the prefix (the frames are
    of the track driven the other way round); a merge copies it again and keeps the prefix."""
    from weather_gym.camera.config import CameraConfig
    from weather_gym.lab.datasets.merge import merge_coco
    from weather_gym.tracks import load_track

    csv = tmp_path / "elsewhere" / "my_oval.csv"
    csv.parent.mkdir()
    load_track("oval").to_csv(csv)
    root = tmp_path / "ds"
    render_dataset(root, tracks=[f"reverse:{csv}"], frames=2, frames_per_episode=2,
                   camera=CameraConfig(width=64, height=36), progress=False)
    ds = load_coco(root)
    assert ds.record(0)["track"] == "reverse:tracks/my_oval.csv"
    assert ds.track_spec(0) == f"reverse:{(root / 'tracks' / 'my_oval.csv').resolve()}"
    assert load_track(ds.track_spec(0)).cone_classes.tobytes() == load_track(f"reverse:{csv}").cone_classes.tobytes()
    ds.close()
    other = tmp_path / "other"
    render_dataset(other, tracks=["oval"], frames=2, frames_per_episode=2, camera=CameraConfig(width=64, height=36),
                   progress=False)
    merged = tmp_path / "merged"
    merge_coco([root, other], merged)
    m = load_coco(merged)
    assert m.record(0)["track"] == "reverse:tracks/s0_my_oval.csv" and load_track(m.track_spec(0)).name == "reverse:s0_my_oval"
    m.close()


def test_start_window_renders_the_approach_to_the_start_line(tmp_path):
    # a user who needs more frames of the start line's big orange cones (rare in a uniform render)
    # asks for start points just before it; the window is recorded with the dataset
    path = render_dataset(tmp_path / "ds", tracks=["small_track"], frames=6, seed=3, start_window=(-20.0, -5.0),
                          frames_per_episode=3, progress=False)
    ds = load_coco(path.parent)
    assert ds.data["info"]["start_window"] == [-20.0, -5.0]
    big = [a for a in ds.data["annotations"] if a["category_id"] == 4 and not a["iscrowd"]]
    assert len({a["image_id"] for a in big}) == 6  # the start line's big orange cones are in every frame


def test_frames_go_through_the_default_camera_model_unless_told_otherwise(tmp_path):
    """Rendered sets go through the env's default camera model; ``--camera-model ideal`` renders the
    frames exactly as rendered (the study's ideal camera), and a TOML file of fields changes one stage."""
    from weather_gym.camera.isp import CameraModel
    from weather_gym.cli import main

    kw = dict(tracks=["oval"], frames=2, seed=5, frames_per_episode=2, progress=False)
    render_dataset(tmp_path / "default", **kw)
    render_dataset(tmp_path / "ideal", camera_model=CameraModel.ideal(), **kw)
    (tmp_path / "cam.toml").write_text("jpeg_quality = 0\nread_noise = 0.0\n")
    assert main(["dataset", "render", "--track", "oval", "--frames", "2", "--seed", "5", "--frames-per-episode",
                 "2", "--camera-model", str(tmp_path / "cam.toml"), "--quiet", "--out", str(tmp_path / "toml")]) == 0
    default, ideal, toml = (load_coco(tmp_path / n) for n in ("default", "ideal", "toml"))
    model = {n: CameraModel.from_dict(d.record(0)["camera_model"]) for n, d in
             (("default", default), ("ideal", ideal), ("toml", toml))}
    assert model == {"default": CameraModel.realistic(), "ideal": CameraModel.ideal(),
                     "toml": CameraModel.realistic().with_(jpeg_quality=0, read_noise=0.0)}
    assert default.record(0)["pose"] == ideal.record(0)["pose"]  # the same views, other frames
    assert not np.array_equal(default.image(0), ideal.image(0))
    assert not np.array_equal(default.image(0), toml.image(0))
    view = ideal.render_view(0)  # the ideal camera's record re-renders byte for byte
    ideal.close()
    assert np.array_equal(view["image"], ideal.image(0))


def test_a_set_without_the_shadow_map_says_so_and_re_renders_its_frames(tmp_path):
    """``--shadows off``: the same views and labels, EGL frames without PyBullet's shadow map; the set
    records it (so its id differs from the default set's) and its views re-render byte for byte."""
    from weather_gym.cli import main
    from weather_gym.core._io import file_id
    from weather_gym.sim.egl import shadow_map as egl_shadow_map
    from weather_gym.sim.renderer import egl_used

    kw = dict(tracks=["oval"], frames=2, seed=5, frames_per_episode=2, progress=False)
    render_dataset(tmp_path / "default", **kw)
    egl = egl_used()  # the set was drawn by EGL in this process (else by TinyRenderer)
    if egl and egl_shadow_map.unavailable_reason() is not None:
        pytest.skip(f"EGL without a shadow-map switch here: {egl_shadow_map.unavailable_reason()}")
    assert main(["dataset", "render", "--track", "oval", "--frames", "2", "--seed", "5", "--frames-per-episode",
                 "2", "--shadows", "off", "--quiet", "--out", str(tmp_path / "off")]) == 0
    default, off = load_coco(tmp_path / "default"), load_coco(tmp_path / "off")
    assert "shadows" not in default.info and "shadows" not in default.record(0)  # default sets as before
    assert off.info["shadows"] is False and off.record(0)["shadows"] is False
    assert off.record(0)["pose"] == default.record(0)["pose"]
    assert [a["bbox"] for a in off.data["annotations"]] == [a["bbox"] for a in default.data["annotations"]]
    assert file_id(tmp_path / "off" / "annotations.json") != file_id(tmp_path / "default" / "annotations.json")
    view = off.render_view(0)
    off.close()
    assert np.array_equal(view["image"], off.image(0))
    # EGL draws its shadow map unless told not to; TinyRenderer draws none either way
    assert np.array_equal(default.image(0), off.image(0)) == (not egl)


def test_jpeg_quality_stores_the_same_frames_as_jpeg_with_the_same_labels(rendered, tmp_path):
    import cv2

    root = tmp_path / "jpg"
    render_dataset(root, jpeg_quality=90, **KW)
    png, jpg = load_coco(rendered), load_coco(root)
    assert [r["file_name"] for r in jpg.images] == [f"images/{i:06d}.jpg" for i in range(4)]
    assert jpg.data["annotations"] == png.data["annotations"]
    for i in range(len(png)):
        # the JPEG of the very frame the PNG holds (lossless), at quality 90: same bytes
        ok, buf = cv2.imencode(".jpg", cv2.imread(str(png.image_path(i))), [cv2.IMWRITE_JPEG_QUALITY, 90])
        assert ok and jpg.image_path(i).read_bytes() == buf.tobytes()
        assert np.abs(jpg.image(i).astype(int) - png.image(i).astype(int)).mean() < 3.0
        np.testing.assert_array_equal(jpg.depth(i), png.depth(i))


@pytest.mark.parametrize("quality", [0, 101, 90.5])
def test_a_bad_jpeg_quality_is_refused_before_anything_is_written(tmp_path, quality):
    from weather_gym.core.errors import InputError

    with pytest.raises(InputError, match="jpeg_quality"):
        render_dataset(tmp_path / "bad", jpeg_quality=quality, **KW)
    assert not (tmp_path / "bad" / "annotations.json").exists()
