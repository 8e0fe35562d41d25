"""The bad inputs of ``tests/test_bad_input.py``: one table, easy to extend.

A :class:`Case` is either a command line (``argv``, run through ``weather_gym.cli.main`` in this
process) or a Python call (``call(w)`` with ``w`` the :class:`World` of prepared files). Every case
must fail cleanly: exit status 2 (CLI) or a :class:`weather_gym.core.errors.WeatherGymError` (Python),
an ``error:`` line (or message) containing ``culprit``, no input changed and nothing written
outside ``out``. ``{w}`` in ``argv``, ``culprit`` and ``out`` is the world folder.

To add a case: append a ``Case`` to :data:`CASES` (and, if it needs a file, create it in
:func:`build_world`). Keep each case fast: it must fail before any long work starts.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

W, H = 96, 54


@dataclass(frozen=True)
class Case:
    id: str
    culprit: str
    argv: tuple[str, ...] | None = None
    call: Callable[[World], Any] | None = None
    out: str | None = None
    """Relative path (below the world folder) that the case may change; nothing else may change."""
    forbid: str | None = None
    """Text that must not appear in the error (e.g. a line of a private file)."""


@dataclass(frozen=True)
class World:
    root: Path

    def __getitem__(self, rel: str) -> Path:
        return self.root / rel


# --------------------------------------------------------------------------------------------- files
def _frame(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (H, W, 3), dtype=np.uint8)


def _write_png(path: Path, rgb: np.ndarray) -> None:
    import cv2

    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


def _dataset(root: Path, frames: int) -> None:
    from weather_gym.camera.config import CameraConfig
    from weather_gym.lab.datasets.coco import CocoWriter

    cam = CameraConfig(width=W, height=H)
    with CocoWriter(root) as writer:
        for i in range(frames):
            writer.add(_frame(i), {"track": "oval", "pose": [0.0, 0.0, 0.0], "speed": 1.0, "yaw_rate": 0.0,
                                   "camera": cam.to_dict()},
                       {"boxes": np.array([[10.0, 10.0, 20.0, 30.0]]), "classes": np.array([0])},
                       depth=np.full((H, W), 5.0, np.float32))


def _edit(src: Path, dst: Path, change: Callable[[dict], None]) -> None:
    shutil.copytree(src, dst)
    data = json.loads((dst / "annotations.json").read_text())
    change(data)
    (dst / "annotations.json").write_text(json.dumps(data))


def _cones(path: Path, rows: list[tuple[str, float, float]]) -> None:
    path.write_text("tag,x,y,direction,x_variance,y_variance,xy_covariance\n"
                    + "".join(f"{t},{x!r},{y!r},0.0,0.01,0.01,0.0\n" for t, x, y in rows))


def build_world(root: Path) -> World:
    """Every file the cases read (made once per test session, in a few seconds)."""
    import cv2

    w = World(root)
    _dataset(w["ds"], frames=4)
    _dataset(w["ds_empty"], frames=0)
    victim = w["victim.png"]
    _write_png(victim, _frame(99))
    (w["victim.csv"]).write_text("private,data\n")
    _edit(w["ds"], w["ds_abs"], lambda d: d["images"][0].update(file_name=str(victim)))
    _edit(w["ds"], w["ds_dotdot"], lambda d: d["images"][0].update(file_name="../victim.png"))
    _edit(w["ds"], w["ds_depth_abs"], lambda d: d["images"][1].update(depth_file=str(victim)))
    _edit(w["ds"], w["ds_track_out"], lambda d: d["images"][0].update(track="../victim.csv"))
    _edit(w["ds"], w["ds_bbox"], lambda d: d["annotations"][0].update(bbox=[1, 2, -3, 4]))
    shutil.copytree(w["ds"], w["ds_badjson"])
    w["ds_badjson/annotations.json"].write_text('{"images": [')
    shutil.copytree(w["ds"], w["ds_link"], ignore=shutil.ignore_patterns("images"))
    (w["elsewhere"]).mkdir()
    shutil.copytree(w["ds/images"], w["elsewhere/images"])
    w["ds_link/images"].symlink_to(w["elsewhere/images"])
    w["no_annotations"].mkdir()
    w["o"].mkdir()  # an existing output folder: a case tests one bad input, not also a missing folder

    _write_png(w["img.png"], _frame(5))
    _write_png(w["strip.png"], np.zeros((1, 5000, 3), np.uint8))
    w["text.png"].write_text("this is not an image\n")
    for name in ("a.png", "b.png", "c.png"):
        _write_png(w[f"imgs/{name}"], _frame(7))
    w["imgs/b.png"].write_bytes(w["imgs/b.png"].read_bytes()[:60])  # truncated PNG
    depth = np.full((10, 10), 1000, np.uint16)
    assert cv2.imwrite(str(w["depth_small.png"]), depth)
    vw = cv2.VideoWriter(str(w["clip.mp4"]), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (W, H))
    for i in range(3):
        vw.write(_frame(i))
    vw.release()

    _cones(w["collinear.csv"], [("blue" if i % 2 else "yellow", float(i), 0.0) for i in range(40)])
    _cones(w["huge.csv"], [("blue", 1e308, 0.0), ("yellow", 0.0, 3.0), ("blue", 5.0, 0.0), ("yellow", 5.0, 3.0)])
    w["secret.txt"].write_text("SECRET-PASSWORD-LINE\nroot:x:0:0\n")
    w["model_bad.toml"].write_text('[[effects]]\nname = "snow"\nk = 0.3\n')
    w["corrupt.onnx"].write_bytes(b"\x00not an onnx model" * 10)
    w["scen_env5.toml"].write_text('id = "WeatherGym/Bad-v0"\nenv = 5\n')
    w["scen_sev9.toml"].write_text('id = "WeatherGym/Bad-v0"\n[weather]\ncondition = "low_light"\nseverity = 9\n')
    w["scen_track_out.toml"].write_text('id = "WeatherGym/Bad-v0"\n[env]\ntrack = "../victim.csv"\n')
    w["scen_rev_track_out.toml"].write_text('id = "WeatherGym/Bad-v0"\n[env]\ntrack = "reverse:../victim.csv"\n')
    w["measured_bad.csv"].write_text("condition,severity,map\nideal,0,0.8\ndroplets,two,0.6\n")
    w["afile"].write_text("a file, not a folder\n")
    for name in ("exists.png", "exists.csv", "exists.json", "exists.mp4", "exists.toml", "exists.md"):
        w[name].write_text("a user's file\n")
    w["eval_report"].mkdir()
    w["eval_report/report.md"].write_text("someone's notes\n")
    w["eval_resdir/results.csv"].mkdir(parents=True)
    w["sweep_plot"].mkdir()
    w["sweep_plot/curves.png"].write_text("someone's plot\n")
    w["gap_out"].mkdir()
    w["gap_out/report.json"].write_text("{}\n")
    _import_sources(w)
    _input_output_sources(w)
    return w


def _import_sources(w: World) -> None:
    """KITTI folders with one fault each, a mask of the wrong size, an ONNX matching no YOLO layout."""
    row = "blue_cone 0.00 0 0.00 10.00 10.00 20.00 30.00 0.36 0.25 0.25 4.0 1.0 -0.9 0.00\n"
    for name in ("kitti_ok", "kitti_nolabel", "kitti_unmapped", "kitti_sizes"):
        _write_png(w[f"{name}/images/000001.png"], _frame(11))
        w[f"{name}/labels"].mkdir(parents=True)
        w[f"{name}/labels/000001.txt"].write_text(row)
    _write_png(w["kitti_nolabel/images/000002.png"], _frame(12))
    w["kitti_unmapped/labels/000001.txt"].write_text(row.replace("blue_cone", "weird_cone"))
    _write_png(w["kitti_sizes/images/000002.png"], np.zeros((20, 30, 3), np.uint8))
    w["kitti_sizes/labels/000002.txt"].write_text("")
    _write_png(w["mask_small.png"], np.zeros((10, 10, 3), np.uint8))
    try:
        import onnx
        from onnx import TensorProto, helper
    except ImportError:  # pragma: no cover - the dev extra has onnx
        return
    inp = helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 32, 32])
    out = helper.make_tensor_value_info("out", TensorProto.FLOAT, [1, 5, 5, 5])
    model = helper.make_model(helper.make_graph(
        [helper.make_node("ReduceMean", ["images"], ["m"], keepdims=0),
         helper.make_node("Expand", ["m", "shape"], ["out"])], "odd", [inp], [out],
        [onnx.numpy_helper.from_array(np.array([1, 5, 5, 5], np.int64), "shape")]),
        opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(w["odd.onnx"]))


# --------------------------------------------------------------------------------------- Python calls
def _make_env(**kwargs):
    import gymnasium as gym

    import weather_gym  # noqa: F401

    kwargs.setdefault("camera", {"width": 64, "height": 36})
    return gym.make("WeatherGym/ConeTrack-v0", **kwargs)


def _reset_with(options):
    env = _make_env()
    try:
        env.reset(seed=0, options=options)
    finally:
        env.close()


def _step_after_close(_w):
    env = _make_env()
    env.reset(seed=0)
    env.close()
    env.step(np.zeros(2, np.float32))


def _motion_blur(_w):
    from weather_gym.weather import make

    make("motion_blur", k=0.5)(np.zeros((120, 160, 3), np.uint8), state={"yaw_rate": 1e8})


def _run_cells_into_dir(w):
    from weather_gym.lab.evaluation.runner import run_cells

    run_cells([{"x": 1}], _square, w["eval_resdir/results.csv"], backend="serial", progress=False)


def _square(cell):
    return {"y": cell["x"] ** 2}


def _evaluate_laps0(w):
    from weather_gym.lab.evaluation.evaluate import EvalConfig, evaluate

    evaluate(EvalConfig(agents=("gt_pure_pursuit",), effects=("droplets",), severities=(0,), seeds=(0,),
                        perception="oracle", laps=0), w["eval_new"], backend="serial", progress=False)


def _py(fn: Callable[..., Any]) -> Callable[[World], Any]:
    return fn


# ---------------------------------------------------------------------------------------------- table
def _cli(id: str, culprit: str, *argv: str, out: str | None = None, forbid: str | None = None) -> Case:
    return Case(id=id, culprit=culprit, argv=tuple(argv), out=out, forbid=forbid)


DEG = ("--weather", "dim:0.5")
EV = ("evaluate", "--agent", "gt_pure_pursuit", "--perception", "oracle", "--effects", "droplets",
      "--severities", "0", "--seeds", "1", "--backend", "serial", "--quiet")

CASES: list[Case] = [
    # ---- degrade
    _cli("degrade-missing-input", "nope.png", "degrade", "{w}/nope.png", "{w}/o/x.png", *DEG, out="o"),
    _cli("degrade-k-out-of-range", "k", "degrade", "{w}/img.png", "{w}/o/x.png", "--weather", "dim:2",
         out="o"),
    _cli("degrade-unknown-effect", "snow", "degrade", "{w}/img.png", "{w}/o/x.png", "--weather", "snow:0.5",
         out="o"),
    _cli("degrade-param-without-value", "persistent", "degrade", "{w}/img.png", "{w}/o/x.png", "--weather",
         "droplets:0.5:persistent", out="o"),
    _cli("degrade-no-weather", "--weather", "degrade", "{w}/img.png", "{w}/o/x.png", out="o"),
    _cli("degrade-output-without-extension", "noext", "degrade", "{w}/img.png", "{w}/o/noext", *DEG, out="o"),
    _cli("degrade-output-exists", "exists.png", "degrade", "{w}/img.png", "{w}/exists.png", *DEG),
    _cli("degrade-empty-weather", "empty weather spec", "degrade", "{w}/img.png", "{w}/o/x.png", "--weather", "",
         out="o"),
    _cli("degrade-weather-param-syntax", "mode", "degrade", "{w}/img.png", "{w}/o/x.png", "--weather",
         "dim:0.5:mode", out="o"),
    _cli("degrade-truncated-image-in-folder", "b.png", "degrade", "{w}/imgs", "{w}/o_imgs", *DEG, "--quiet",
         out="o_imgs"),
    _cli("degrade-video-to-image", "x.png", "degrade", "{w}/clip.mp4", "{w}/o/x.png", *DEG, out="o"),
    _cli("degrade-unknown-input-kind", "secret.txt", "degrade", "{w}/secret.txt", "{w}/o/x.png", *DEG, out="o"),
    _cli("degrade-depth-size-mismatch", "depth_small.png", "degrade", "{w}/img.png", "{w}/o/x.png", "--weather",
         "fog:0.5", "--depth", "{w}/depth_small.png", out="o"),
    # ---- detector
    _cli("detector-eval-json-onto-the-labels", "annotations.json", "detector", "eval", "{w}/ds", "--limit", "2",
         "--json", "{w}/ds/annotations.json"),
    _cli("detector-eval-missing-dataset", "nope", "detector", "eval", "{w}/nope"),
    _cli("detector-eval-limit-zero", "--limit", "detector", "eval", "{w}/ds", "--limit", "0"),
    _cli("detector-eval-limit-negative", "--limit", "detector", "eval", "{w}/ds", "--limit", "-3"),
    _cli("detector-eval-no-images", "ds_empty", "detector", "eval", "{w}/ds_empty"),
    _cli("detector-eval-bad-json", "annotations.json", "detector", "eval", "{w}/ds_badjson"),
    _cli("detector-eval-bad-bbox", "bbox", "detector", "eval", "{w}/ds_bbox"),
    _cli("detector-eval-depth-outside", "depth_file", "detector", "eval", "{w}/ds_depth_abs"),
    _cli("detector-eval-corrupt-model", "corrupt.onnx", "detector", "eval", "{w}/ds", "--model",
         "{w}/corrupt.onnx"),
    _cli("detector-eval-threads-zero", "threads", "detector", "eval", "{w}/ds", "--threads", "0"),
    _cli("detector-eval-weather-without-k", "dim", "detector", "eval", "{w}/ds", "--weather", "dim"),
    _cli("detector-eval-json-under-a-file", "afile", "detector", "eval", "{w}/ds", "--json", "{w}/afile/r.json"),
    _cli("detector-eval-empty-weather", "empty weather spec", "detector", "eval", "{w}/ds", "--weather", ""),
    _cli("detector-predict-1x5000", "strip.png", "detector", "predict", "{w}/strip.png", "--out", "{w}/o/p.png",
         out="o"),
    _cli("detector-predict-not-an-image", "text.png", "detector", "predict", "{w}/text.png", "--out",
         "{w}/o/p.png", out="o"),
    _cli("detector-predict-out-exists", "exists.png", "detector", "predict", "{w}/img.png", "--out",
         "{w}/exists.png"),
    _cli("detector-predict-threshold", "threshold", "detector", "predict", "{w}/img.png", "--out", "{w}/o/p.png",
         "--threshold", "2", out="o"),
    _cli("detector-sweep-k-grid-out-of-range", "--k-grid", "detector", "sweep", "{w}/ds", "--k-grid", "0,2"),
    _cli("detector-sweep-json-exists", "exists.json", "detector", "sweep", "{w}/ds", "--k-grid", "0", "--weather",
         "dim", "--json", "{w}/exists.json"),
    _cli("detector-figure-index", "--index", "detector", "figure", "{w}/ds", "--index", "99", "--out",
         "{w}/o/f.png", out="o"),
    _cli("detector-figure-out-exists", "exists.png", "detector", "figure", "{w}/ds", "--out", "{w}/exists.png"),
    _cli("detector-train-out-suffix", "m.txt", "detector", "train", "--data", "{w}/ds", "--out", "{w}/o/m.txt",
         out="o"),
    _cli("detector-train-mix-count", "--mix", "detector", "train", "--data", "{w}/ds", "--mix", "0.5,0.5", "--out",
         "{w}/o/m.onnx", out="o"),
    _cli("detector-train-mix-negative", "--mix", "detector", "train", "--data", "{w}/ds", "--mix", "-1", "--out",
         "{w}/o/m.onnx", out="o"),
    _cli("detector-train-mix-not-numbers", "--mix", "detector", "train", "--data", "{w}/ds", "--mix", "a", "--out",
         "{w}/o/m.onnx", out="o"),
    _cli("detector-train-epoch-frames-without-mix", "--epoch-frames", "detector", "train", "--data", "{w}/ds",
         "--epoch-frames", "10", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-init-missing", "nosuch.onnx", "detector", "train", "--data", "{w}/ds", "--init",
         "{w}/nosuch.onnx", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-init-not-onnx", "exists.json", "detector", "train", "--data", "{w}/ds", "--init",
         "{w}/exists.json", "--max-steps", "1", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-distractors-not-probability", "distractors", "detector", "train", "--data", "{w}/ds",
         "--distractors", "1.5", "--out", "{w}/o/m.onnx", out="o"),
    # ---- dataset
    _cli("dataset-render-zero-frames", "frames", "dataset", "render", "--track", "oval", "--frames", "0", "--out",
         "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-unknown-track", "nosuch", "dataset", "render", "--track", "nosuch", "--frames", "2",
         "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-huge-camera", "width", "dataset", "render", "--track", "oval", "--frames", "2",
         "--width", "100000", "--height", "100000", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-over-a-dataset", "annotations.json", "dataset", "render", "--track", "oval", "--frames",
         "2", "--out", "{w}/ds"),
    _cli("dataset-render-out-is-a-file", "afile", "dataset", "render", "--track", "oval", "--frames", "2",
         "--out", "{w}/afile"),
    _cli("dataset-render-randomize-bad-range", "exposure_ev", "dataset", "render", "--track", "oval", "--frames",
         "2", "--randomize", "--randomize-set", "exposure_ev=3,-1", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-randomize-unknown-key", "nosuch_key", "dataset", "render", "--track", "oval", "--frames",
         "2", "--randomize", "--randomize-set", "nosuch_key=0,1", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-randomize-not-a-number", "k1", "dataset", "render", "--track", "oval", "--frames",
         "2", "--randomize", "--randomize-set", "k1=a,b", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-randomize-ranges-missing", "nosuch.toml", "dataset", "render", "--track", "oval",
         "--frames", "2", "--randomize", "--randomize-ranges", "{w}/nosuch.toml", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-ranges-without-randomize", "--randomize", "dataset", "render", "--track", "oval",
         "--frames", "2", "--randomize-set", "k1=-0.1,0", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-start-window-not-two-numbers", "--start-window", "dataset", "render", "--track", "oval",
         "--frames", "2", "--start-window=-30", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-start-window-empty", "LOW < HIGH", "dataset", "render", "--track", "oval",
         "--frames", "2", "--start-window=-3,-30", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-start-window-off-open-track", "acceleration", "dataset", "render", "--track",
         "acceleration", "--frames", "2", "--start-window=-40,-3", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-bad-scene", "scene", "dataset", "render", "--track", "oval", "--frames", "2",
         "--scene", "mars", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-unknown-camera-model", "--camera-model", "dataset", "render", "--track", "oval", "--frames",
         "2", "--camera-model", "fisheye", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-camera-model-file-missing", "nosuch_cam.toml", "dataset", "render", "--track", "oval",
         "--frames", "2", "--camera-model", "{w}/nosuch_cam.toml", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-render-camera-model-with-randomized-realistic", "--camera-model", "dataset", "render", "--track",
         "oval", "--frames", "2", "--randomize", "--camera-model", "ideal", "--out", "{w}/o_ds", out="o_ds"),
    _cli("dataset-info-dotdot-file-name", "file_name", "dataset", "info", "{w}/ds_dotdot"),
    _cli("dataset-info-absolute-file-name", "file_name", "dataset", "info", "{w}/ds_abs"),
    _cli("dataset-info-track-outside", "'track'", "dataset", "info", "{w}/ds_track_out"),
    _cli("dataset-info-symlink-out", "file_name", "dataset", "info", "{w}/ds_link"),
    _cli("dataset-info-no-annotations", "annotations.json", "dataset", "info", "{w}/no_annotations"),
    # ---- tracks
    _cli("train-unknown-hyperparams-section", "Nope", "train", "--out", "{w}/o/run", "--hyperparams-key", "Nope",
         out="o"),
    _cli("train-eval-track-is-a-training-track", "hairpin", "train", "--out", "{w}/o/run", "--track", "hairpin",
         "--eval-track", "hairpin", out="o"),
    _cli("tracks-show-collinear-cones", "collinear.csv", "tracks", "show", "{w}/collinear.csv", "--out",
         "{w}/o/t.png", out="o"),
    _cli("tracks-show-huge-coordinates", "huge.csv", "tracks", "show", "{w}/huge.csv", "--out", "{w}/o/t.png",
         out="o"),
    _cli("tracks-show-a-private-file", "secret.txt", "tracks", "show", "{w}/secret.txt", "--out", "{w}/o/t.png",
         out="o", forbid="SECRET-PASSWORD-LINE"),
    _cli("tracks-show-unknown", "nosuch", "tracks", "show", "nosuch", "--out", "{w}/o/t.png", out="o"),
    _cli("tracks-show-out-exists", "exists.png", "tracks", "show", "oval", "--out", "{w}/exists.png"),
    _cli("tracks-show-neither-track-nor-all", "--all", "tracks", "show", "--out", "{w}/o/t.png", out="o"),
    _cli("tracks-export-bad-random-seed", "random:x", "tracks", "export", "random:x", "--out", "{w}/o/t.csv",
         out="o"),
    _cli("tracks-export-random-unknown-arg", "start_pair", "tracks", "export", "random:3,pairs=0.3", "--out",
         "{w}/o/t.csv", out="o"),
    _cli("tracks-export-random-arg-not-a-number", "start_pair", "tracks", "export", "random:3,start_pair=x",
         "--out", "{w}/o/t.csv", out="o"),
    _cli("tracks-export-random-pair-out-of-range", "start_pair", "tracks", "export", "random:3,start_pair=9",
         "--out", "{w}/o/t.csv", out="o"),
    _cli("tracks-export-out-exists", "exists.csv", "tracks", "export", "oval", "--out", "{w}/exists.csv"),
    # ---- lap
    _cli("lap-zero-laps", "--laps", "lap", "--laps", "0"),
    _cli("lap-unknown-agent", "nosuch", "lap", "--agent", "nosuch"),
    _cli("lap-bad-preset-severity", "9", "lap", "--weather", "droplets@9"),
    _cli("lap-empty-weather", "empty weather spec", "lap", "--weather", ""),
    _cli("lap-video-not-mp4", "v.avi", "lap", "--video", "{w}/o/v.avi", out="o"),
    _cli("lap-video-exists", "exists.mp4", "lap", "--video", "{w}/exists.mp4"),
    _cli("lap-collinear-track", "collinear.csv", "lap", "--track", "{w}/collinear.csv"),
    _cli("lap-missing-detector", "nope.onnx", "lap", "--perception", "detector", "--detector", "{w}/nope.onnx"),
    _cli("lap-agent-arg-syntax", "v_max", "lap", "--agent-arg", "v_max"),
    _cli("lap-unknown-env", "Nope/Env-v0", "lap", "--env-id", "Nope/Env-v0"),
    _cli("lap-surrogate-two-effects", "one weather effect at a time", "lap", "--perception", "surrogate",
         "--weather", "droplets@3,low_light@1", "--max-steps", "5"),
    _cli("lap-surrogate-video", "perception surrogate renders none", "lap", "--perception", "surrogate",
         "--video", "{w}/o/s.mp4", out="o"),
    # ---- surrogate
    _cli("evaluate-surrogate-unknown-effect", "hail", "evaluate", "--agent",
         "gt_pure_pursuit", "--perception", "surrogate", "--effects", "hail", "--severities", "0,2", "--seeds", "1",
         "--backend", "serial", "--quiet", "--out", "{w}/o_ev_sur", out="o_ev_sur"),
    _cli("surrogate-log-two-effects", "one weather effect at a time", "surrogate", "log", "--weather",
         "fog@1,droplets@3", "--steps", "5",
         "--out", "{w}/o/l.npz", out="o"),
    _cli("surrogate-log-zero-steps", "--steps", "surrogate", "log", "--steps", "0", "--out", "{w}/o/l.npz", out="o"),
    _cli("surrogate-log-not-npz", "l.csv", "surrogate", "log", "--out", "{w}/o/l.csv", out="o"),
    _cli("surrogate-log-bad-seeds", "--seed-list", "surrogate", "log", "--seed-list", "0,x", "--out", "{w}/o/l.npz", out="o"),
    _cli("surrogate-fit-not-a-log", "text.png", "surrogate", "fit", "{w}/text.png", "--out", "{w}/o/m.npz", out="o"),
    _cli("surrogate-fit-missing-log", "nope.npz", "surrogate", "fit", "{w}/nope.npz", "--out", "{w}/o/m.npz", out="o"),
    _cli("surrogate-validate-missing-model", "nope.npz", "surrogate", "validate", "--model", "{w}/nope.npz",
         "--out", "{w}/o/val", out="o"),
    _cli("surrogate-validate-bad-severity", "severities", "surrogate", "validate", "--severities", "7",
         "--out", "{w}/o/val", out="o"),
    # ---- evaluate
    _cli("evaluate-severity-not-an-integer", "--severities", *EV[:8], "0,x", *EV[9:], "--out", "{w}/o_ev",
         out="o_ev"),
    _cli("evaluate-severity-out-of-range", "7", *EV[:8], "7", *EV[9:], "--out", "{w}/o_ev", out="o_ev"),
    _cli("evaluate-workers-zero", "--workers", *EV, "--workers", "0", "--out", "{w}/o_ev", out="o_ev"),
    _cli("evaluate-workers-10000", "--workers", *EV[:-3], "--workers", "10000", "--quiet", "--out", "{w}/o_ev",
         out="o_ev"),
    _cli("evaluate-agent-kwargs-not-json", "--agent-kwargs", *EV, "--agent-kwargs", "{bad", "--out", "{w}/o_ev",
         out="o_ev"),
    _cli("evaluate-collinear-track", "collinear.csv", *EV, "--track", "{w}/collinear.csv", "--out", "{w}/o_ev",
         out="o_ev"),
    _cli("evaluate-zero-laps", "laps", *EV, "--laps", "0", "--out", "{w}/o_ev", out="o_ev"),
    _cli("evaluate-negative-max-steps", "max_steps", *EV, "--max-steps", "-1", "--out", "{w}/o_ev", out="o_ev"),
    _cli("evaluate-results-path-is-a-folder", "results.csv", *EV, "--out", "{w}/eval_resdir"),
    _cli("evaluate-someones-report", "report.md", *EV, "--out", "{w}/eval_report"),
    _cli("evaluate-missing-presets", "nope.toml", *EV, "--presets", "{w}/nope.toml", "--out", "{w}/o_ev",
         out="o_ev"),
    _cli("evaluate-huge-camera", "width", *EV, "--env-kwargs", '{"camera": {"width": 100000, "height": 100000}}',
         "--out", "{w}/o_ev", out="o_ev"),
    # ---- sweep
    _cli("sweep-k-out-of-range", "--k-grid", "sweep", "--weather", "dim", "--k-grid", "0:2:0.5", "--dataset",
         "{w}/ds", "--out", "{w}/o_sw", out="o_sw"),
    _cli("sweep-missing-dataset", "nope", "sweep", "--weather", "dim", "--dataset", "{w}/nope", "--out",
         "{w}/o_sw", out="o_sw"),
    _cli("sweep-unknown-effect", "snow", "sweep", "--weather", "snow", "--dataset", "{w}/ds", "--out", "{w}/o_sw",
         out="o_sw"),
    _cli("sweep-fixed-k", "k is left open", "sweep", "--weather", "dim:0.5", "--dataset", "{w}/ds", "--out",
         "{w}/o_sw", out="o_sw"),
    _cli("sweep-someones-plot", "curves.png", "sweep", "--weather", "dim", "--k-grid", "0", "--seeds", "1", "--dataset",
         "{w}/ds", "--backend", "serial", "--quiet", "--out", "{w}/sweep_plot"),
    # ---- calibrate
    _cli("calibrate-missing-curve", "nope.csv", "calibrate", "--curve", "{w}/nope.csv", "--measured",
         "{w}/measured_bad.csv", "--out", "{w}/o/p.toml", out="o"),
    _cli("calibrate-out-exists", "exists.toml", "calibrate", "--curve", "{w}/nope.csv", "--measured",
         "{w}/measured_bad.csv", "--out", "{w}/exists.toml"),
    _cli("calibrate-not-a-curve-file", "exists.csv", "calibrate", "--curve", "{w}/exists.csv",
         "--measured", "{w}/measured_bad.csv", "--out", "{w}/o/p.toml", out="o"),
    # ---- dataset import / mask, detector specs, gap with a clear reference (issue 10)
    _cli("import-unknown-format", "voc", "dataset", "import", "voc", "{w}/kitti_ok", "--out", "{w}/o_import",
         out="o_import"),
    _cli("import-missing-source", "nope", "dataset", "import", "kitti", "{w}/nope", "--out", "{w}/o_import",
         out="o_import"),
    _cli("import-missing-labels", "000002.txt", "dataset", "import", "kitti", "{w}/kitti_nolabel", "--out",
         "{w}/o_import", out="o_import"),
    _cli("import-class-map-leaves-a-class-out", "weird_cone", "dataset", "import", "kitti", "{w}/kitti_unmapped",
         "--out", "{w}/o_import", out="o_import"),
    _cli("import-mixed-sizes-with-intrinsics", "--intrinsics", "dataset", "import", "kitti", "{w}/kitti_sizes",
         "--intrinsics", "90,90,48,27", "--out", "{w}/o_import", out="o_import"),
    _cli("import-bad-class-target", "purple", "dataset", "import", "kitti", "{w}/kitti_ok", "--classes",
         "blue_cone=purple", "--out", "{w}/o_import", out="o_import"),
    _cli("import-bad-intrinsics", "intrinsics", "dataset", "import", "kitti", "{w}/kitti_ok", "--intrinsics",
         "900,1", "--out", "{w}/o_import", out="o_import"),
    _cli("import-mask-wrong-size", "mask_small.png", "dataset", "import", "kitti", "{w}/kitti_ok", "--mask",
         "{w}/mask_small.png", "--out", "{w}/o_import", out="o_import"),
    _cli("import-out-not-empty", "imgs", "dataset", "import", "kitti", "{w}/kitti_ok", "--out", "{w}/imgs"),
    _cli("mask-set-wrong-size", "mask_small.png", "dataset", "mask", "{w}/ds", "--set", "{w}/mask_small.png"),
    _cli("mask-out-exists", "exists.png", "dataset", "mask", "{w}/ds", "--out", "{w}/exists.png"),
    _cli("detector-eval-onnx-matching-no-layout", "odd.onnx", "detector", "eval", "{w}/ds", "--detector",
         "yolo:{w}/odd.onnx", "--detector-classes", "0=blue"),
    _cli("detector-eval-unknown-detector-kind", "detr", "detector", "eval", "{w}/ds", "--detector", "detr:x.onnx"),
    _cli("gap-too-few-frames", "at least 8", "gap", "{w}/ds", "--out", "{w}/o_gap", out="o_gap"),
    _cli("gap-same-camera-without-reference", "--reference", "gap", "{w}/ds", "--mode", "same-camera", "--out",
         "{w}/o_gap", out="o_gap"),
    _cli("gap-bad-scene", "cartoon", "gap", "{w}/ds", "--scene", "cartoon", "--out", "{w}/o_gap", out="o_gap"),
    _cli("gap-unknown-camera-model", "--camera-model", "gap", "{w}/ds", "--camera-model", "pinhole", "--out",
         "{w}/o_gap", out="o_gap"),
    _cli("gap-missing-reference", "nope", "gap", "{w}/ds", "--reference", "{w}/nope", "--out", "{w}/o_gap",
         out="o_gap"),
    # ---- gap
    _cli("gap-missing-measured", "nope", "gap", "{w}/nope", "--out", "{w}/o_gap", out="o_gap"),
    _cli("gap-bad-model", "model_bad.toml", "gap", "{w}/ds", "--model", "{w}/model_bad.toml", "--out",
         "{w}/o_gap", out="o_gap"),
    _cli("gap-held-out-fraction", "held_out", "gap", "{w}/ds", "--held-out", "1.5", "--out", "{w}/o_gap",
         out="o_gap"),
    _cli("gap-report-exists", "report.json", "gap", "{w}/ds", "--out", "{w}/gap_out"),
    # ---- bench
    _cli("bench-bad-size", "96by64", "bench", "weather", "--sizes", "96by64"),
    _cli("bench-out-exists", "exists.md", "bench", "weather", "--out", "{w}/exists.md"),
    _cli("bench-env-out-exists", "exists.md", "bench", "env", "--out", "{w}/exists.md"),
    _cli("bench-env-bad-resolution", "672by376", "bench", "env", "--resolutions", "672by376"),
    # ---- Python entry points
    Case("py-gym-make-huge-camera", "width", call=lambda w: _make_env(camera={"width": 100000, "height": 100000})),
    Case("py-gym-make-collinear-track", "collinear.csv", call=lambda w: _make_env(track=str(w["collinear.csv"]))),
    Case("py-gym-make-cast-shadows-not-a-bool", "cast_shadows",
         call=lambda w: _make_env(sim={"scene": "realistic", "cast_shadows": "yes"})),
    Case("py-reset-options-not-a-dict", "options", call=lambda w: _reset_with("x")),
    Case("py-reset-start-pose-not-numbers", "start_pose", call=lambda w: _reset_with({"start_pose": ["a", 1, 2]})),
    Case("py-step-after-close", "closed", call=_step_after_close),
    Case("py-motion-blur-yaw-rate-1e8", "yaw_rate", call=_motion_blur),
    Case("py-effect-k-out-of-range", "k", call=lambda w: __import__("weather_gym.weather", fromlist=["make"])
         .make("blur", k=2)),
    Case("py-parse-empty-weather", "empty weather spec", call=lambda w: __import__(
        "weather_gym.weather", fromlist=["parse_weather"]).parse_weather("")),
    Case("py-load-coco-dotdot", "file_name", call=lambda w: __import__(
        "weather_gym.lab.datasets.coco", fromlist=["load_coco"]).load_coco(w["ds_dotdot"])),
    Case("py-degrade-dataset-absolute-file-name", "file_name", out="o_degraded", call=lambda w: __import__(
        "weather_gym.lab.gap", fromlist=["degrade_dataset"]).degrade_dataset(w["ds_abs"], w["o_degraded"], "blur:0.6")),
    Case("py-load-track-huge-coordinates", "huge.csv", call=lambda w: __import__(
        "weather_gym.tracks", fromlist=["load_track"]).load_track(str(w["huge.csv"]))),
    Case("py-run-cells-results-path-is-a-folder", "results.csv", call=_run_cells_into_dir),
    Case("py-scenario-env-not-a-table", "scen_env5.toml", call=lambda w: __import__(
        "weather_gym.envs.scenario", fromlist=["load_scenario"]).load_scenario(w["scen_env5.toml"])),
    Case("py-scenario-severity-9", "scen_sev9.toml", call=lambda w: __import__(
        "weather_gym.envs.scenario", fromlist=["load_scenario"]).load_scenario(w["scen_sev9.toml"])),
    Case("py-scenario-track-outside", "track", call=lambda w: __import__(
        "weather_gym.envs.scenario", fromlist=["load_scenario"]).load_scenario(w["scen_track_out.toml"])),
    Case("py-scenario-reversed-track-outside", "track", call=lambda w: __import__(
        "weather_gym.envs.scenario", fromlist=["load_scenario"]).load_scenario(w["scen_rev_track_out.toml"])),
    Case("py-depth-quantile-above-1", "depth_quantile", call=lambda w: __import__(
        "weather_gym.perception.ranging", fromlist=["detections_to_cones"]).detections_to_cones(
            {"boxes": np.zeros((1, 4)), "scores": np.ones(1), "classes": np.zeros(1, int)},
            __import__("weather_gym.camera.config", fromlist=["CameraConfig"]).CameraConfig(),
            np.ones((376, 672), np.float32), depth_quantile=1.5)),
    Case("py-detector-corrupt-model", "corrupt.onnx", call=lambda w: __import__(
        "weather_gym.perception", fromlist=["ConeDetector"]).ConeDetector(w["corrupt.onnx"])),
    Case("py-render-dataset-zero-frames", "frames", out="o_render", call=lambda w: __import__(
        "weather_gym.lab.datasets.render", fromlist=["render_dataset"]).render_dataset(
            w["o_render"], tracks=["oval"], frames=0, progress=False)),
    Case("py-evaluate-zero-laps", "laps", out="eval_new", call=_evaluate_laps0),
    Case("py-measured-table-bad-severity", "measured_bad.csv", call=lambda w: __import__(
        "weather_gym.lab.calibration.measured", fromlist=["load_measured"]).load_measured([str(w["measured_bad.csv"])])),
    Case("py-read-model-unknown-effect", "model_bad.toml", call=lambda w: __import__(
        "weather_gym.lab.gap.weather_model", fromlist=["read_model"]).read_model(w["model_bad.toml"])),
]


# ------------------------------------------- an input is never an output; resume identity; user input
def _input_output_sources(w: World) -> None:
    """Files of the cases below: logs, a model inside an output folder, non-UTF-8 files, journals."""
    from weather_gym.surrogate.log import _TABLES, SurrogateLog, _stack, save_log

    tables = [_stack({}, cols) for cols in _TABLES.values()]
    save_log(SurrogateLog(*tables, [{"condition": "droplets", "k": 0.5, "track": "oval"}], {}), w["log_noweather.npz"])
    import io
    import zipfile

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)})
    with zipfile.ZipFile(w["log_huge.npz"], "w") as z:
        z.writestr("cones/range.npy", header.getvalue() + bytes(64))
    w["gapm"].mkdir()
    w["gapm/model.toml"].write_text("# the clean simulator\n")
    _edit(w["ds"], w["ds_wide"], lambda d: d["images"][1].update(width=20000, height=100))  # past the frame bound
    latin1 = "# caf\xe9 r\xe9glage\n".encode("latin-1")
    w["latin1.toml"].write_bytes(latin1 + b'[[effects]]\nname = "dim"\nk = 0.3\n')
    w["latin1.csv"].write_bytes(latin1 + b"condition,severity,map\nideal,0,0.8\n")
    w["o_resume"].mkdir()  # an interrupted render of seed 5 (its journal's settings line)
    w["o_resume/annotations.partial.jsonl"].write_text(json.dumps({"settings": {"seed": 5}}) + "\n")
    w["o_train"].mkdir()  # a training checkpoint of seed 5 on ds
    from dataclasses import asdict

    import torch

    from weather_gym.lab.training.detector.train import TrainConfig

    torch.save({"config": asdict(TrainConfig(seed=5)), "data": [str(w["ds"])]}, w["o_train/m.onnx.ckpt"])


def _reset_env(**options):
    return lambda w: _reset_with(options)


def _vec_env_million(_w):
    from weather_gym.pipeline import make_vec_env

    make_vec_env(num_envs=10**6, vectorization_mode="sync")


TR = ("detector", "train", "--data", "{w}/ds")

CASES += [
    # ---- an input is never an output (--overwrite or not)
    _cli("detector-eval-json-onto-the-labels-overwrite", "is never an output", "detector", "eval", "{w}/ds",
         "--limit", "1", "--json", "{w}/ds/annotations.json", "--overwrite"),
    _cli("mask-out-onto-a-frame", "000000.png", "dataset", "mask", "{w}/ds", "--out", "{w}/ds/images/000000.png",
         "--overwrite"),
    _cli("mask-preview-onto-a-frame", "--preview", "dataset", "mask", "{w}/ds", "--out", "{w}/o/m.png", "--preview",
         "{w}/ds/images/000000.png", "--overwrite", out="o"),
    _cli("surrogate-fit-out-onto-the-log", "is never an output", "surrogate", "fit", "{w}/log_noweather.npz",
         "--out", "{w}/log_noweather.npz", "--overwrite"),
    _cli("gap-out-is-the-reference", "is never an output", "gap", "{w}/ds", "--reference", "{w}/ds_empty", "--out",
         "{w}/ds_empty", "--overwrite"),
    _cli("gap-out-is-the-measured-set", "is never an output", "gap", "{w}/ds", "--out", "{w}/ds"),
    _cli("gap-out-inside-the-measured-set", "is never an output", "gap", "{w}/ds", "--out", "{w}/ds/gap"),
    _cli("gap-model-inside-out", "model.toml", "gap", "{w}/ds", "--model", "{w}/gapm/model.toml", "--out",
         "{w}/gapm", "--overwrite"),
    _cli("degrade-folder-into-itself", "inside it", "degrade", "{w}/imgs", "{w}/imgs/out", *DEG),
    # ---- resume identity
    _cli("dataset-render-resume-other-seed", "seed", "dataset", "render", "--track", "oval", "--frames", "2",
         "--seed", "6", "--resume", "--out", "{w}/o_resume", out="o_resume"),
    _cli("detector-train-resume-other-seed", "seed", *TR, "--seed", "6", "--out", "{w}/o_train/m.onnx",
         out="o_train"),
    # ---- seeds
    _cli("degrade-negative-seed", "--seed", "degrade", "{w}/img.png", "{w}/o/x.png", *DEG, "--seed", "-1", out="o"),
    _cli("dataset-render-negative-seed", "--seed", "dataset", "render", "--track", "oval", "--frames", "2",
         "--seed", "-3", "--out", "{w}/o_ds", out="o_ds"),
    _cli("detector-eval-negative-seed", "--seed", "detector", "eval", "{w}/ds", "--seed", "-1"),
    _cli("lap-negative-seed", "--seed", "lap", "--seed", "-1"),
    _cli("surrogate-log-negative-seed", "--seed-list", "surrogate", "log", "--seed-list", "0,-1", "--out", "{w}/o/l.npz",
         out="o"),
    _cli("surrogate-validate-negative-seed", "--surrogate-seeds", "surrogate", "validate", "--surrogate-seeds", "-2",
         "--out", "{w}/o/val", out="o"),
    _cli("detector-train-negative-seed", "--seed", *TR, "--seed", "-1", "--out", "{w}/o/m.onnx", out="o"),
    # ---- detector training options
    _cli("detector-train-lr-negative", "--lr", *TR, "--lr", "-1", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-lr-nan", "--lr", *TR, "--lr", "nan", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-threads-zero", "--threads", *TR, "--threads", "0", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-max-steps-zero", "--max-steps", *TR, "--max-steps", "0", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-warmup-negative", "--warmup", *TR, "--warmup", "-5", "--out", "{w}/o/m.onnx", out="o"),
    _cli("detector-train-input-size-huge", "--input-size", *TR, "--input-size", "100000", "100000", "--out",
         "{w}/o/m.onnx", out="o"),
    # ---- files that are not UTF-8, or not what they claim
    _cli("gap-model-not-utf8", "latin1.toml", "gap", "{w}/ds", "--model", "{w}/latin1.toml", "--out", "{w}/o_gap",
         out="o_gap"),
    _cli("evaluate-presets-not-utf8", "latin1.toml", *EV, "--presets", "{w}/latin1.toml", "--out", "{w}/o_ev",
         out="o_ev"),
    _cli("calibrate-curve-not-utf8", "latin1.csv", "calibrate", "--curve", "{w}/latin1.csv", "--measured",
         "{w}/measured_bad.csv", "--out", "{w}/o/p.toml", out="o"),
    Case("py-measured-table-not-utf8", "latin1.csv", call=lambda w: __import__(
        "weather_gym.lab.calibration.measured", fromlist=["load_measured"]).load_measured([str(w["latin1.csv"])])),
    Case("py-presets-base-not-utf8", "latin1.toml", call=lambda w: __import__(
        "weather_gym.weather.presets", fromlist=["load_presets"]).load_presets(w["latin1.toml"])),
    _cli("surrogate-fit-episode-without-weather", "weather", "surrogate", "fit", "{w}/log_noweather.npz", "--out",
         "{w}/o/m.npz", out="o"),
    _cli("surrogate-fit-header-claims-1e12-elements", "log_huge.npz", "surrogate", "fit", "{w}/log_huge.npz",
         "--out", "{w}/o/m.npz", out="o"),
    # ---- sizes and ranges: one frame bound, physical reset options
    _cli("import-intrinsics-1e300", "--intrinsics", "dataset", "import", "kitti", "{w}/kitti_ok", "--intrinsics",
         "1e300,900,48,27", "--out", "{w}/o_import", out="o_import"),
    _cli("detector-eval-20000x100-frame", "20000x100", "detector", "eval", "{w}/ds_wide"),
    _cli("detector-eval-detector-input-huge", "--detector-input", "detector", "eval", "{w}/ds", "--detector",
         "yolov8:{w}/odd.onnx", "--detector-input", "100000x100000"),
    Case("py-reset-start-speed-1e6", "start_speed", call=_reset_env(start_speed=1e6)),
    Case("py-reset-friction-1e9", "friction", call=_reset_env(friction=1e9)),
    Case("py-make-vec-env-a-million", "num_envs", call=_vec_env_million),
    # ---- arguments of agents and perception, checked before any cell runs
    _cli("evaluate-agent-arg-unknown-key", "--agent-arg", *EV, "--agent-arg", "vmax=3", "--out",
         "{w}/o_ev", out="o_ev"),
    _cli("evaluate-perception-kwargs-unknown-key", "--perception-kwargs", *EV, "--perception-kwargs",
         '{"noise_level": 3}', "--out", "{w}/o_ev", out="o_ev"),
]
