"""YOLO-family ONNX exports behind the Detector protocol, tested with tiny graphs built here.

Each graph outputs fixed raw predictions (plus 0 x the input, so that it depends on the image):
the adapter must recognise the layout, decode, suppress duplicates, map classes and undo the
letterbox / stretch, so that the boxes land on the frame's pixels.
"""

from __future__ import annotations

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from weather_gym.perception.detector_spec import as_detector, load_detector  # noqa: E402
from weather_gym.perception.yolo import YoloDetector  # noqa: E402


def make_onnx(path, outputs: dict[str, np.ndarray], *, input_shape=(1, 3, 64, 64), names=None, imgsz=None):
    """A graph ``images -> outputs`` whose outputs are the given constants (+ 0 x mean(input))."""
    nodes = [helper.make_node("ReduceMean", ["images"], ["m"], keepdims=0), helper.make_node("Mul", ["m", "zero"], ["z"])]
    inits = [numpy_helper.from_array(np.array(0.0, np.float32), "zero")]
    outs = []
    for name, value in outputs.items():
        value = np.asarray(value)
        inits.append(numpy_helper.from_array(value, f"{name}_c"))
        if value.dtype == np.float32:
            nodes.append(helper.make_node("Add", [f"{name}_c", "z"], [name]))
            elem = TensorProto.FLOAT
        else:
            nodes.append(helper.make_node("Identity", [f"{name}_c"], [name]))
            elem = helper.np_dtype_to_tensor_dtype(value.dtype)
        outs.append(helper.make_tensor_value_info(name, elem, list(value.shape)))
    inp = helper.make_tensor_value_info("images", TensorProto.FLOAT, list(input_shape))
    model = helper.make_model(helper.make_graph(nodes, "yolo_test", [inp], outs, inits),
                              opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    meta = {}
    if names is not None:
        meta["names"] = repr(dict(enumerate(names)))
    if imgsz is not None:
        meta["imgsz"] = repr(list(imgsz))
    for k, v in meta.items():
        model.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


# two cones in input pixels of a 64x64 input: (cx, cy, w, h), class, score; a duplicate of the first
CONES = [((16.0, 32.0, 8.0, 16.0), 0, 0.9), ((48.0, 40.0, 6.0, 12.0), 1, 0.8), ((16.5, 32.0, 8.0, 16.0), 0, 0.6)]


def raw_v8(nc=3, n=20):
    p = np.zeros((1, 4 + nc, n), np.float32)
    for j, (xywh, c, s) in enumerate(CONES):
        p[0, :4, j] = xywh
        p[0, 4 + c, j] = s
    p[0, :4, len(CONES):] = [[5.0], [5.0], [4.0], [4.0]]
    p[0, 4:, len(CONES):] = 0.01  # background below the threshold
    return p


def raw_v5(nc=3, n=20):
    p = np.zeros((1, n, 5 + nc), np.float32)
    for j, (xywh, c, s) in enumerate(CONES):
        p[0, j, :4] = xywh
        p[0, j, 4] = 1.0
        p[0, j, 5 + c] = s
    return p


def nms6(k=10):
    p = np.zeros((1, k, 6), np.float32)
    for j, (xywh, c, s) in enumerate(CONES[:2]):
        cx, cy, w, h = xywh
        p[0, j] = [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2, s, c]
    return p


# A 128x64 frame letterboxed into 64x64: scale 0.5, pad y = 16. Expected frame boxes of the two cones:
LETTERBOX = [[24.0, 16.0, 40.0, 48.0], [90.0, 36.0, 102.0, 60.0]]
FRAME = np.zeros((64, 128, 3), np.uint8)


@pytest.mark.parametrize("kind, outputs", [
    ("yolov8", {"output0": raw_v8()}),
    ("yolov5", {"output0": raw_v5()}),
    ("yolo", {"output0": raw_v8()}),
    ("yolo", {"output0": raw_v5()}),
    ("yolo", {"output0": nms6()}),
])
def test_each_layout_decodes_to_frame_pixels(kind, outputs, tmp_path):
    path = make_onnx(tmp_path / "m.onnx", outputs)
    det = load_detector(f"{kind}:{path}", classes="0=blue,1=yellow,2=orange")
    d = det(FRAME)
    assert d.classes.tolist() == [0, 1]  # the duplicate is suppressed (or was, in the graph)
    np.testing.assert_allclose(d.boxes, LETTERBOX, atol=1e-4)
    np.testing.assert_allclose(d.scores, [0.9, 0.8], atol=1e-6)
    assert det.input_size == (64, 64) and det.resize == "letterbox"


def test_other_nms_graph_outputs(tmp_path):
    """(K, 7) rows [batch x1 y1 x2 y2 class score], and num_dets / boxes / scores / classes."""
    rows = np.array([[0, 12, 24, 20, 40, 0, 0.9], [0, 45, 34, 51, 46, 1, 0.8]], np.float32)
    d = load_detector(f"yolo:{make_onnx(tmp_path / 'a.onnx', {'output': rows})}", classes="0=blue,1=yellow")(FRAME)
    np.testing.assert_allclose(d.boxes, LETTERBOX, atol=1e-4)
    four = {"num_dets": np.array([[2]], np.int64), "det_boxes": rows[None, :, 1:5],
            "det_scores": rows[None, :, 6], "det_classes": rows[None, :, 5].astype(np.int64)}
    d = load_detector(f"yolo:{make_onnx(tmp_path / 'b.onnx', four)}", classes="0=blue,1=yellow")(FRAME)
    assert d.classes.tolist() == [0, 1]
    np.testing.assert_allclose(d.boxes, LETTERBOX, atol=1e-4)


def test_stretch_any_input_size_and_batches(tmp_path):
    path = make_onnx(tmp_path / "m.onnx", {"output0": raw_v8()}, input_shape=(1, 3, 64, 64))
    det = YoloDetector(path, classes="0=blue,1=yellow,2=orange", resize="stretch")
    d = det(FRAME)  # 128x64 stretched to 64x64: x / 0.5, y / 1
    np.testing.assert_allclose(d.boxes[0], [24.0, 24.0, 40.0, 40.0], atol=1e-4)
    # a dynamic input: the size comes from the caller (or the export's metadata)
    dyn = make_onnx(tmp_path / "dyn.onnx", {"output0": raw_v8()}, input_shape=("batch", 3, "h", "w"))
    with pytest.raises(ValueError, match="dynamic input size"):
        YoloDetector(dyn, classes="0=blue,1=yellow,2=orange")
    det = YoloDetector(dyn, classes="0=blue,1=yellow,2=orange", input_size=(64, 64))
    out = det.detect_batch([FRAME, FRAME])
    assert len(out) == 2 and out[1].classes.tolist() == [0, 1]
    meta = make_onnx(tmp_path / "meta.onnx", {"output0": raw_v8()}, input_shape=(1, 3, "h", "w"), imgsz=(64, 64),
                     names=["blue_cone", "yellow_cone", "unknown_cone"])
    det = load_detector(f"yolov8:{meta}")  # class names from the export, mapped like an import
    assert det.input_size == (64, 64) and det(FRAME).classes.tolist() == [0, 1]


def test_class_map_ignore_drops_and_a_class_left_out_is_an_error(tmp_path):
    path = make_onnx(tmp_path / "m.onnx", {"output0": raw_v8()})
    d = load_detector(f"yolov8:{path}", classes="0=blue,*=ignore")(FRAME)
    assert d.classes.tolist() == [0]
    with pytest.raises(ValueError, match=r"output class\(es\) 2 are not in the class map"):
        load_detector(f"yolov8:{path}", classes="0=blue,1=yellow")
    with pytest.raises(ValueError, match="names no classes"):
        load_detector(f"yolov8:{path}")


def test_outputs_matching_no_layout_are_a_clear_error(tmp_path):
    path = make_onnx(tmp_path / "odd.onnx", {"out": np.zeros((1, 5, 5, 5), np.float32)})
    with pytest.raises(ValueError, match=r"odd.onnx: outputs \[\(1, 5, 5, 5\)\] match no YOLO layout .*; expected \(1, N, 5\+nc\) YOLOv5"):
        load_detector(f"yolo:{path}", classes="0=blue")
    v5 = make_onnx(tmp_path / "v5.onnx", {"output0": raw_v5()})
    with pytest.raises(ValueError, match="class map names output index 3 but the export has 3 classes"):
        load_detector(f"yolov5:{v5}", classes="0=blue,1=yellow,2=orange,3=big_orange")
    with pytest.raises(FileNotFoundError, match="detector model nope.onnx not found"):
        load_detector("yolov8:nope.onnx", classes="0=blue")
    with pytest.raises(ValueError, match="expected conenet, conenet:PATH, yolov8:PATH"):
        load_detector("detr:x.onnx")


def test_a_plain_function_is_a_detector_and_the_wrapper_takes_specs(tmp_path):
    import gymnasium as gym

    from weather_gym.perception import Detections
    from weather_gym.wrappers import DetectorWrapper

    def mine(frame):
        return Detections(np.array([[10, 10, 20, 40.]], np.float32), np.array([0.9], np.float32), np.array([1]))

    assert len(as_detector(mine)(FRAME)) == 1

    class Camera(gym.Env):
        observation_space = gym.spaces.Box(0, 255, (64, 128, 3), np.uint8)
        action_space = gym.spaces.Discrete(1)

        def reset(self, *, seed=None, options=None):
            return FRAME, {}

        def step(self, action):
            return FRAME, 0.0, False, False, {}

    env = DetectorWrapper(Camera(), mine)
    obs, info = env.reset(seed=0)
    assert int(obs["mask"].sum()) == 1 and info["detections"]["classes"].tolist() == [1]
    path = make_onnx(tmp_path / "m.onnx", {"output0": raw_v8()})
    env = DetectorWrapper(Camera(), f"yolov8:{path}", detector_classes="0=blue,1=yellow,2=orange")
    obs, info = env.reset(seed=0)
    assert int(obs["mask"].sum()) == 2


def test_every_command_takes_the_detector_options(tmp_path, capsys):
    """detector eval scores with a YOLO export (its too-small rule at the export's input scale); evaluate
    hands the options to its DetectorWrapper; a bad spec fails before anything runs."""
    import argparse

    from weather_gym.cli import main
    from weather_gym.cli.evaluate import _perception_kwargs
    from weather_gym.lab.datasets.coco import CocoWriter

    path = make_onnx(tmp_path / "m.onnx", {"output0": raw_v8()})
    with CocoWriter(tmp_path / "ds") as w:
        w.add(FRAME, {}, {"boxes": np.array(LETTERBOX), "classes": np.array([0, 1])})
    assert main(["detector", "eval", str(tmp_path / "ds"), "--detector", f"yolov8:{path}",
                 "--detector-classes", "0=blue,1=yellow,2=orange"]) == 0
    out = capsys.readouterr().out
    assert "mAP@0.5      1.000" in out and "6.1 px at the detector's 64x64 input, letterbox x0.5" in out
    args = argparse.Namespace(perception_kwargs=None, perception="detector", detector=f"yolov8:{path}",
                              detector_classes="0=blue,1=yellow,2=orange", detector_resize="stretch",
                              detector_input=None, detector_threshold=0.4)
    assert _perception_kwargs(args) == {"detector": f"yolov8:{path}", "detector_classes": "0=blue,1=yellow,2=orange",
                                        "detector_resize": "stretch", "score_threshold": 0.4}
    assert main(["detector", "eval", str(tmp_path / "ds"), "--detector", "yolov8:missing.onnx"]) == 2
    assert "detector model missing.onnx not found" in capsys.readouterr().err


def test_a_yolo_detector_copies_as_its_arguments(tmp_path):
    import copy
    import pickle

    path = make_onnx(tmp_path / "m.onnx", {"output0": raw_v8()}, input_shape=(1, 3, 64, 64))
    det = YoloDetector(path, classes="0=blue,1=yellow,2=orange", resize="stretch", score_threshold=0.4)
    for twin in (copy.deepcopy(det), pickle.loads(pickle.dumps(det))):
        assert twin.session is not det.session and (twin.resize, twin.score_threshold) == ("stretch", 0.4)
        np.testing.assert_array_equal(twin(FRAME).boxes, det(FRAME).boxes)
