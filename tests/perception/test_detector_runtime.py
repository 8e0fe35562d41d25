"""The shipped ONNX detector at run time: loading, bad files, inputs, batches."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cone_synth import synth_frame

from weather_gym.perception import DEFAULT_MODEL, ConeDetector, Detections


@pytest.fixture(scope="module")
def detector():
    return ConeDetector(threads=1)


def test_shipped_model_and_sidecar_exist_and_are_small():
    assert DEFAULT_MODEL.is_file() and DEFAULT_MODEL.with_suffix(".json").is_file()
    assert DEFAULT_MODEL.stat().st_size < 3_000_000
    meta = json.loads(DEFAULT_MODEL.with_suffix(".json").read_text())
    assert meta["classes"] == ["blue", "yellow", "orange", "big_orange"]
    assert meta["flops"] < 0.8e9


def test_frame_without_cones_gives_an_empty_valid_result(detector):
    d = detector(np.zeros((376, 672, 3), np.uint8))
    assert isinstance(d, Detections) and len(d) == 0
    assert d.boxes.shape == (0, 4) and d.scores.shape == (0,) and d.classes.shape == (0,)


def test_batch_equals_single_frames_and_boxes_are_in_original_pixels(detector, rng):
    frames = [synth_frame(rng)[0] for _ in range(3)]
    single = [detector(f, score_threshold=0.05) for f in frames]
    batch = detector(np.stack(frames), score_threshold=0.05)
    assert len(batch) == 3
    for a, b in zip(single, batch, strict=True):
        np.testing.assert_allclose(a.boxes, b.boxes, atol=1e-3)
        np.testing.assert_allclose(a.scores, b.scores, atol=1e-5)
        assert (a.boxes[:, [0, 2]] <= 672).all() and (a.boxes[:, [1, 3]] <= 376).all()
        assert (a.scores >= 0.05).all() and (np.diff(a.scores) <= 1e-7).all()
    # another frame size works too (letterboxed): 1280x720
    big = detector(np.zeros((720, 1280, 3), np.uint8))
    assert len(big) == 0


def test_score_threshold_filters(detector, rng):
    frame = synth_frame(rng)[0]
    lo = detector(frame, score_threshold=0.01)
    hi = detector(frame, score_threshold=0.6)
    assert len(hi) <= len(lo)
    assert (hi.scores >= 0.6).all()


def test_missing_model_names_the_file(tmp_path):
    path = tmp_path / "nope.onnx"
    with pytest.raises(FileNotFoundError, match="nope.onnx"):
        ConeDetector(path)


def test_corrupt_model_names_the_file(tmp_path):
    path = tmp_path / "broken.onnx"
    path.write_bytes(b"this is not a protobuf" * 10)
    with pytest.raises(ValueError, match="broken.onnx"):
        ConeDetector(path)


def test_model_with_wrong_input_shape_is_rejected(tmp_path):
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    inp = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 1, 32, 32])
    out = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 1, 32, 32])
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g", [inp], [out])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    path = tmp_path / "gray.onnx"
    onnx.save(model, str(path))
    with pytest.raises(ValueError, match=r"gray\.onnx.*input shape"):
        ConeDetector(path)


def test_sidecar_input_size_mismatch_is_rejected(tmp_path):
    onnx = pytest.importorskip("onnx")

    path = tmp_path / "m.onnx"
    model = onnx.load(str(DEFAULT_MODEL))
    for dim, v in zip(model.graph.input[0].type.tensor_type.shape.dim[2:], (288, 512), strict=True):
        dim.dim_value = v  # a fixed-input export (the shipped one's height and width are symbolic)
    onnx.save(model, str(path))
    meta = json.loads(DEFAULT_MODEL.with_suffix(".json").read_text())
    meta["input_size"] = [640, 352]
    path.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="640x352"):
        ConeDetector(path)


@pytest.mark.parametrize("change, message", [
    ({"stride": 0}, r"stride must be an integer >= 1, got 0"),
    ({"classes": []}, r"classes must be a list of at least 1 non-empty strings, got \[\]"),
    ({"reference_camera": "672x376"}, r"reference_camera must be 2 values, each an integer >= 1, got '672x376'"),
    ({"score_threshold": 1.5}, r"score_threshold must be a finite number in \[0, 1\], got 1.5"),
])
def test_a_bad_sidecar_key_names_the_file_key_value_and_range(tmp_path, change, message):
    from weather_gym.core.errors import FileFormatError
    from weather_gym.perception.onnx_detector import load_model_metadata

    meta = {**json.loads(DEFAULT_MODEL.with_suffix(".json").read_text()), **change}
    (tmp_path / "m.json").write_text(json.dumps(meta))
    assert load_model_metadata(DEFAULT_MODEL) == json.loads(DEFAULT_MODEL.with_suffix(".json").read_text())
    with pytest.raises(FileFormatError, match=r"model metadata .*m\.json: " + message):
        load_model_metadata(tmp_path / "m.onnx")


@pytest.mark.parametrize("bad", [np.zeros((376, 672), np.uint8), np.zeros((376, 672, 3), np.float32),
                                 np.zeros((0, 672, 3), np.uint8)])
def test_bad_images_raise(detector, bad):
    with pytest.raises(ValueError):
        detector(bad)


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="threads"):
        ConeDetector(threads=0)
    with pytest.raises(ValueError, match="score_threshold"):
        ConeDetector(score_threshold=1.5)


def test_a_detector_object_passes_through_gym_make_and_pickle(detector, rng):
    """gym.make deep-copies its keyword arguments and a vector env pickles them: the detector is copied
    as its constructor arguments (its own onnxruntime session), and detects the same."""
    import copy
    import pickle

    import gymnasium as gym

    from weather_gym import make_env

    frame = synth_frame(rng)[0]
    strict = ConeDetector(threads=1, score_threshold=0.2, max_detections=5)
    for twin in (copy.deepcopy(strict), pickle.loads(pickle.dumps(strict))):
        assert twin.session is not strict.session
        assert (twin.score_threshold, twin.max_detections, twin.path) == (0.2, 5, strict.path)
        a, b = strict(frame), twin(frame)
        np.testing.assert_array_equal(a.boxes, b.boxes)
        np.testing.assert_array_equal(a.scores, b.scores)
    env = make_env(track="small_track", perception="detector", detector=detector, max_episode_steps=3)
    try:
        assert env.spec is not None and isinstance(env.unwrapped, gym.Env)
        env.reset(seed=0)
        _, _, _, _, info = env.step(env.action_space.sample())
        assert "detections" in info
    finally:
        env.close()
