"""The ConeNet input follows the camera (672x376 -> 512x288, 336x188 -> 256x160) unless pinned."""

from __future__ import annotations

import numpy as np
import pytest
from cone_synth import synth_frame

from weather_gym.core.errors import InputError, LimitError
from weather_gym.perception.detector_spec import DetectorSpec, detector_id, load_detector, parse_detector_spec
from weather_gym.perception.onnx_detector import ConeDetector, input_size_for


@pytest.fixture(scope="module")
def follow():
    return ConeDetector(threads=1)


@pytest.fixture(scope="module")
def pinned():
    return ConeDetector(threads=1, input_size=(512, 288))


def same(a, b) -> bool:
    return (a.boxes.tobytes(), a.scores.tobytes(), a.classes.tobytes()) == (
        b.boxes.tobytes(), b.scores.tobytes(), b.classes.tobytes())


def test_input_follows_the_camera_at_the_native_scale(follow):
    assert input_size_for(672, 376) == follow.input_size_for(672, 376) == follow.input_size == (512, 288)
    assert input_size_for(336, 188) == follow.input_size_for(336, 188) == (256, 160)  # 336 x 512/672 = 256
    assert input_size_for(1280, 720) == input_size_for(4096, 4096) == (512, 288)  # never above the native input
    assert input_size_for(480, 640) == (384, 288) and input_size_for(8, 8) == (32, 32)
    assert all(v % 32 == 0 for v in input_size_for(401, 233))
    assert follow.follow and "input=follow" in repr(follow)


def test_the_shipped_graph_runs_at_the_followed_size(follow):
    assert [type(v) for v in follow.session.get_inputs()[0].shape[2:]] == [str, str]  # symbolic H, W
    out, lbs = follow.raw([np.zeros((188, 336, 3), np.uint8)])
    assert out.shape == (1, 8, 80, 128) and lbs[0].scale == pytest.approx(256 / 336)


def test_outputs_at_672x376_are_identical_to_the_pinned_512x288(follow, pinned, rng):
    frames = [synth_frame(rng)[0] for _ in range(3)]
    for f in frames:
        a, b = follow(f, score_threshold=0.05), pinned(f, score_threshold=0.05)
        assert len(a) > 0 and same(a, b)
    assert all(same(a, b) for a, b in zip(follow(np.stack(frames)), pinned(np.stack(frames)), strict=True))


def test_pinned_size_is_honoured(pinned):
    assert not pinned.follow and pinned.input_size_for(336, 188) == pinned.input_size_for(1280, 720) == (512, 288)
    assert ConeDetector(input_size="native").input_size_for(336, 188) == (512, 288)
    det = load_detector("conenet", input_size="256x160")
    assert det.input_size_for(672, 376) == (256, 160) and det.raw([np.zeros((376, 672, 3), np.uint8)])[0].shape == (
        1, 8, 80, 128)
    spec = parse_detector_spec("conenet", input_size="native")
    assert spec.input_size == "native" and "input=native" in str(spec) and not spec.load().follow
    assert parse_detector_spec("conenet", input_size="follow").input_size is None
    assert detector_id(spec) != detector_id(None)


def test_mixed_frame_sizes_in_one_batch_equal_single_frames(follow, rng):
    frames = [synth_frame(rng, size=s)[0] for s in ((672, 376), (336, 188), (672, 376))]
    batch = follow(frames, score_threshold=0.05)
    assert all(same(a, follow(f, score_threshold=0.05)) for a, f in zip(batch, frames, strict=True))


@pytest.mark.parametrize("bad", ["500x288", "512x", (0, 288), (512.5, 288), (3168, 288), "big"])
def test_bad_pinned_size_is_an_input_error_naming_it(bad):
    with pytest.raises(InputError, match="input_size"):
        ConeDetector(input_size=bad)


def test_bad_sizes_elsewhere_are_input_errors():
    with pytest.raises(InputError, match="'wide'"):
        parse_detector_spec("conenet", input_size="wide")
    with pytest.raises(InputError, match="'follow' and 'native' are options of the ConeNet"):
        parse_detector_spec(DetectorSpec("yolov8", "x.onnx"), input_size="follow")
    with pytest.raises(LimitError, match="camera"):
        input_size_for(4, 376)
    with pytest.raises(InputError, match="width"):
        input_size_for(672.0, 376)


def test_a_fixed_input_export_keeps_its_size_and_cannot_follow(tmp_path):
    onnx = pytest.importorskip("onnx")
    from weather_gym.perception import DEFAULT_MODEL

    model = onnx.load(str(DEFAULT_MODEL))
    for dim, v in zip(model.graph.input[0].type.tensor_type.shape.dim[2:], (160, 256), strict=True):
        dim.dim_value = v
    path = tmp_path / "fixed.onnx"
    onnx.save(model, str(path))
    det = ConeDetector(path)  # no sidecar: the graph's size, pinned
    assert not det.follow and det.input_size_for(672, 376) == (256, 160)
    with pytest.raises(InputError, match="cannot follow"):
        ConeDetector(path, input_size="follow")
    with pytest.raises(InputError, match="fixed input 256x160"):
        ConeDetector(path, input_size=(512, 288))


def test_spec_refuses_a_conenet_input_off_the_32_grid_naming_the_option():
    with pytest.raises(InputError, match=r"500x288 \(--detector-input\).*multiple of 32"):
        parse_detector_spec("conenet", input_size="500x288")
