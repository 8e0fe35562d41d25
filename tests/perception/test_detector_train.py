"""The training path stays alive: targets, augmentation, a few steps, ONNX export, onnxruntime load."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from cone_synth import write_synth_dataset  # noqa: E402

from weather_gym.perception.detector import ConeDetector  # noqa: E402
from weather_gym.perception.train import TrainConfig, augment, build_targets, train_detector  # noqa: E402

SMALL = dict(input_size=(256, 160), crop_size=(128, 96), epochs=2, batch_size=2, warmup_iters=1, threads=1)


def test_targets_peak_at_the_box_centre_and_ignore_tiny_cones():
    boxes = np.array([[40, 40, 60, 80], [100, 10, 104, 15.]])
    heat, ign, ind, size, off, mask = build_targets(boxes, np.array([1, 0]), np.array([False, True]), (256, 160))
    assert heat.shape == (4, 40, 64) and mask.sum() == 1
    cy, cx = divmod(int(ind[0]), 64)
    assert (cx, cy) == (12, 15) and heat[1, cy, cx] == 1.0 and heat[0].max() == 0.0
    np.testing.assert_allclose(size[0], np.log([20 / 4, 40 / 4]), rtol=1e-6)
    np.testing.assert_allclose(off[0], [0.5, 0.0])
    assert ign[3, 25] == 1.0 and ign[15, 12] == 0.0


def test_augment_moves_boxes_with_the_image():
    img = np.zeros((376, 672, 3), np.uint8)
    img[100:140, 50:80] = 255
    box = np.array([[50, 100, 80, 140.]])
    cfg = TrainConfig(crop_size=None)
    for seed in range(5):
        out, b, vis = augment(img, box, cfg, np.random.default_rng(seed))
        x1, y1, x2, y2 = np.round(b[0]).astype(int)
        if vis[0] > 0.99:
            inside = out[y1 + 2 : y2 - 2, x1 + 2 : x2 - 2].astype(int)
            assert inside.mean() > 150  # the white patch is where the box says (after colour jitter)
    plain, b, _ = augment(img, box, cfg, None)
    assert plain.shape == (288, 512, 3)
    np.testing.assert_allclose(b[0], box[0] * (512 / 672) + [0, 1, 0, 1], atol=1e-6)


@pytest.mark.slow
def test_a_few_training_steps_export_an_onnx_model_that_runs(tmp_path):
    data = write_synth_dataset(tmp_path / "synth", 6, seed=1)
    out = tmp_path / "m.onnx"
    res = train_detector([data], out, TrainConfig(max_steps=3, **SMALL), val=data, progress=False, log=lambda *_: None)
    assert res["steps"] == 3 and out.is_file() and not (tmp_path / "m.onnx.ckpt").exists()
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["input_size"] == [256, 160] and meta["training"]["config"]["seed"] == 0 and meta["flops"] > 0
    det = ConeDetector(out)
    assert det.input_size == (256, 160)
    d = det(np.zeros((376, 672, 3), np.uint8), score_threshold=0.0)
    assert d.boxes.shape[1] == 4 and np.isfinite(d.boxes).all()
    # same seed, same model
    out2 = tmp_path / "m2.onnx"
    train_detector([data], out2, TrainConfig(max_steps=3, **SMALL), progress=False, log=lambda *_: None)
    x = np.random.default_rng(0).random((1, 3, 160, 256), dtype=np.float32) * 255
    a = det.session.run(None, {"images": x})[0]
    b = ConeDetector(out2).session.run(None, {"images": x})[0]
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)


@pytest.mark.slow
def test_interrupted_training_resumes_from_its_checkpoint(tmp_path):
    data = write_synth_dataset(tmp_path / "synth", 4, seed=2)
    out = tmp_path / "m.onnx"
    cfg = TrainConfig(**SMALL)
    logs = []

    class Stop(Exception):
        pass

    def log(msg):
        logs.append(msg)
        if len(logs) == 1:
            raise Stop  # interrupted after the first epoch's checkpoint
    with pytest.raises(Stop):
        train_detector([data], out, cfg, progress=False, log=log)
    assert (tmp_path / "m.onnx.ckpt").is_file() and not out.exists()
    res = train_detector([data], out, cfg, progress=False, log=logs.append)
    assert any("resuming" in str(m) for m in logs) and res["history"][-1]["epoch"] == 2 and out.is_file()
