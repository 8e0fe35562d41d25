"""The training path stays alive: targets, augmentation, a few steps, ONNX export, onnxruntime load."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from cone_synth import write_synth_dataset  # noqa: E402

from weather_gym.core.errors import FileFormatError, InputError  # noqa: E402
from weather_gym.lab.training.detector.train import TrainConfig, augment, build_targets, train_detector  # noqa: E402
from weather_gym.perception.onnx_detector import ConeDetector  # noqa: E402

SMALL = dict(input_size=(256, 160), crop_size=(128, 96), epochs=2, batch_size=2, warmup_iters=1, threads=1)


def test_targets_peak_at_the_box_centre_and_ignore_tiny_cones():
    boxes = np.array([[40, 40, 60, 80], [100, 10, 104, 15.]])
    heat, ign, ind, size, off, mask = build_targets(boxes, np.array([1, 0]), np.array([False, True]), (256, 160))
    assert heat.shape == (4, 40, 64) and mask.sum() == 1
    cy, cx = divmod(int(ind[0]), 64)
    assert (cx, cy) == (12, 15) and heat[1, cy, cx] == 1.0 and heat[0].max() == 0.0
    np.testing.assert_allclose(size[0], np.log([20 / 4, 40 / 4]), rtol=1e-6)
    np.testing.assert_allclose(off[0], [0.5, 0.0])
    assert ign.shape == (4, 40, 64) and (ign[:, 3, 25] == 1.0).all() and (ign[:, 15, 12] == 0.0).all()
    # own_class: the tiny blue cone is ignored in the blue heatmap only, a negative for the other classes
    ign = build_targets(boxes, np.array([1, 0]), np.array([False, True]), (256, 160), own_class=np.array([False, True]))[1]
    assert ign[0, 3, 25] == 1.0 and (ign[1:, 3, 25] == 0.0).all()


def test_a_stride_2_grid_gives_a_start_line_pair_two_separate_peaks():
    # a start-line pair: the rear cone's visible slice is centred 5 input px right of the front cone
    boxes = np.array([[38, 40, 52, 60], [47, 40, 53, 59.]])
    classes, ignore = np.array([3, 3]), np.array([False, False])

    def cells_apart(stride):
        ind = build_targets(boxes, classes, ignore, (256, 160), stride)[2]
        (y0, x0), (y1, x1) = (divmod(int(i), 256 // stride) for i in ind[:2])
        return max(abs(x1 - x0), abs(y1 - y0))

    assert cells_apart(4) == 1  # neighbouring cells: CenterNet's 3x3 peak filter can keep only one of them
    assert cells_apart(2) >= 2  # the 3x3 peak filter keeps both
    heat, _, ind, size, _, mask = build_targets(boxes, classes, ignore, (256, 160), 2)
    assert heat.shape == (4, 80, 128) and mask.sum() == 2 and ind[0] != ind[1]
    np.testing.assert_allclose(size[1], np.log([6 / 2, 19 / 2]), rtol=1e-6)
    with pytest.raises(InputError, match="stride"):
        TrainConfig(stride=8)


def test_a_stride_2_net_starts_from_a_stride_4_model_and_exports_its_stride(tmp_path):
    from weather_gym.lab.training.detector.conenet import ConeNet, ConeNetExport
    from weather_gym.lab.training.detector.train import export_onnx, load_onnx_weights

    torch.manual_seed(4)
    coarse = export_onnx(ConeNet().eval(), tmp_path / "s4.onnx", (128, 64))
    net = load_onnx_weights(ConeNet(stride=2), coarse).eval()
    x = torch.rand(1, 3, 64, 128) * 255
    with torch.no_grad():  # the finer level starts as the identity: the same sizes, on a finer grid
        fine = ConeNetExport(net)(x)[0, 4:6].numpy()
        ref = ConeNetExport(load_onnx_weights(ConeNet(), coarse).eval())(x)[0, 4:6].numpy()
    assert fine.shape == (2, 32, 64)
    np.testing.assert_allclose(np.median(fine, axis=(1, 2)), np.median(ref, axis=(1, 2)), rtol=0.3)
    path = export_onnx(net, tmp_path / "s2.onnx", (128, 64))
    assert json.loads(path.with_suffix(".json").read_text())["stride"] == 2
    det = ConeDetector(path)
    assert det.stride == 2 and det.raw([np.zeros((64, 128, 3), np.uint8)])[0].shape[-2:] == (32, 64)
    back = load_onnx_weights(ConeNet(stride=2), path).eval()
    with torch.no_grad():
        np.testing.assert_allclose(ConeNetExport(back)(x).numpy(), ConeNetExport(net)(x).numpy(), atol=1e-4)


def test_hidden_cone_targets_give_the_rear_cone_of_a_pair_its_own_heatmap_peak():
    from weather_gym.perception.labels import hidden_mask

    # the front cone of a start pair, the rear cone's slice beside it, and a cone on its own
    boxes = np.array([[38, 40, 52, 60], [52, 38, 56, 57], [120, 40, 134, 60.]])
    classes, ignore = np.array([3, 3, 0]), np.array([False, False, False])
    hidden = hidden_mask(boxes, np.array([4.0, 4.4, 4.0]))
    assert hidden.tolist() == [False, True, False]
    assert hidden_mask(boxes).tolist() == [False, True, False]  # no ranges: the lower box bottom is nearer
    assert hidden_mask(boxes, np.array([4.4, 4.0, 4.0])).tolist() == [True, False, False]
    heat, _, ind, _, _, mask = build_targets(boxes, classes, ignore, (256, 160), 2, hidden)
    assert heat.shape == (8, 80, 128) and mask.sum() == 3
    peaks = {ch: set(np.flatnonzero(heat[ch] == 1.0)) for ch in range(8)}
    assert peaks[3] == {int(ind[0]), int(ind[1])} and peaks[7] == {int(ind[1])} and peaks[4] == set()
    assert build_targets(boxes, classes, ignore, (256, 160), 2)[0].shape == (4, 80, 128)
    with pytest.raises(InputError, match="ranges"):
        hidden_mask(boxes, np.array([1.0]))


def test_a_hidden_cone_net_starts_from_a_plain_model_and_exports_the_plain_output(tmp_path):
    from weather_gym.lab.training.detector.conenet import ConeNet, ConeNetExport
    from weather_gym.lab.training.detector.train import detection_loss, export_onnx, load_onnx_weights

    torch.manual_seed(5)
    plain = export_onnx(ConeNet(stride=2).eval(), tmp_path / "plain.onnx", (128, 64))
    net = load_onnx_weights(ConeNet(stride=2, hidden=True), plain).eval()
    ref = load_onnx_weights(ConeNet(stride=2), plain).eval()
    x = torch.rand(1, 3, 64, 128) * 255
    with torch.no_grad():
        out, base = ConeNetExport(net)(x), ConeNetExport(ref)(x)
    assert out.shape == base.shape == (1, 8, 32, 64)  # the runtime sees the same C+4 channels
    np.testing.assert_allclose(out[:, 4:].numpy(), base[:, 4:].numpy(), rtol=1e-5)  # shared size and offset
    assert (out[:, :4] >= base[:, :4] - 1e-6).all()  # merged peaks: the larger score per class and cell
    path = export_onnx(net, tmp_path / "hidden.onnx", (128, 64))
    assert "hidden-cone" in json.loads(path.with_suffix(".json").read_text())["architecture"]
    assert ConeDetector(path).raw([np.zeros((64, 128, 3), np.uint8)])[0].shape == (1, 8, 32, 64)
    back = load_onnx_weights(ConeNet(stride=2, hidden=True), path).eval()
    with torch.no_grad():
        np.testing.assert_allclose(ConeNetExport(back)(x).numpy(), out.numpy(), atol=1e-5)
    # the hidden heatmaps are trained: a loss term of their own, and an error when their targets are missing
    boxes, classes = np.array([[38, 20, 52, 40], [52, 18, 56, 37.]]), np.array([3, 3])
    t = build_targets(boxes, classes, np.zeros(2, bool), (128, 64), 2, np.array([False, True]))
    batch = [torch.from_numpy(v)[None] for v in t]
    _, parts = detection_loss(net.train()(x / 255), *batch)
    assert parts["hidden"] > 0
    with pytest.raises(InputError, match="hidden-cone net needs 8 heat targets"):
        detection_loss(net(x / 255), batch[0][:, :4], *batch[1:])


def test_hidden_cone_box_targets_point_at_the_rear_cone_from_every_cell_around_it():
    from weather_gym.lab.training.detector.train import HIDDEN_BOX_RADIUS
    from weather_gym.perception.labels import hidden_mask

    boxes = np.array([[38, 40, 52, 60], [52, 38, 56, 57], [120, 40, 134, 60.]])
    classes, ignore = np.array([3, 3, 0]), np.array([False, False, False])
    hidden = hidden_mask(boxes)
    heat, _, ind, size, _, mask, hreg, hmask = build_targets(boxes, classes, ignore, (256, 160), 2, hidden, True)
    assert heat.shape == (8, 80, 128) and hreg.shape == (4, 80, 128) and hmask.shape == (80, 128)
    side = 2 * HIDDEN_BOX_RADIUS + 1
    assert hmask.sum() == side * side  # the rear cone's window only: no box targets for the others
    ys, xs = np.nonzero(hmask)
    cy, cx = divmod(int(ind[1]), 128)
    assert abs(xs - cx).max() == HIDDEN_BOX_RADIUS and abs(ys - cy).max() == HIDDEN_BOX_RADIUS
    # from every cell, cell + offset is the rear cone's centre, and the size is its size
    np.testing.assert_allclose(xs + hreg[2, ys, xs], (52 + 56) / 2 / 2)
    np.testing.assert_allclose(ys + hreg[3, ys, xs], (38 + 57) / 2 / 2)
    np.testing.assert_allclose(hreg[:2, ys, xs].T, np.broadcast_to(size[1], (len(xs), 2)))
    assert len(build_targets(boxes, classes, ignore, (256, 160), 2, hidden)) == 6
    with pytest.raises(InputError, match="hidden mask"):
        build_targets(boxes, classes, ignore, (256, 160), 2, None, True)
    with pytest.raises(InputError, match="hidden_boxes needs hidden"):
        TrainConfig(hidden_boxes=True)


def test_a_net_with_hidden_cone_boxes_reports_them_where_a_hidden_peak_wins(tmp_path):
    from weather_gym.lab.training.detector.conenet import ConeNet, ConeNetExport
    from weather_gym.lab.training.detector.train import detection_loss, export_onnx, load_onnx_weights

    torch.manual_seed(6)
    heads = export_onnx(ConeNet(stride=2, hidden=True).eval(), tmp_path / "heads.onnx", (128, 64))
    net = load_onnx_weights(ConeNet(stride=2, hidden=True, hidden_boxes=True), heads).eval()
    ref = load_onnx_weights(ConeNet(stride=2, hidden=True), heads).eval()
    x = torch.rand(1, 3, 64, 128) * 255
    with torch.no_grad():  # the heatmaps start as the file's
        np.testing.assert_allclose(ConeNetExport(net)(x)[:, :4].numpy(), ConeNetExport(ref)(x)[:, :4].numpy(), atol=1e-6)
        # constant outputs: every hidden cell a peak of 0.99 against main peaks of 0.01, so each cell reports
        # the hidden box (3 x stride wide, offset 1.5 cells), and the main box where the main peak wins
        for conv in (net.out, net.out_hidden):
            conv.weight.zero_()
        net.out.bias[:4] = -4.6
        net.out.bias[4:] = 0.0
        net.out_hidden.bias[:] = torch.tensor([4.6] * 4 + [np.log(3.0), 0.0, 1.5, -0.5])
        out = ConeNetExport(net)(x)
        np.testing.assert_allclose(out[0, 4, 5, 5].item(), 6.0, rtol=1e-5)  # exp(log 3) x stride 2
        np.testing.assert_allclose(out[0, 6:, 5, 5].numpy(), [1.5, -0.5], rtol=1e-5)
        net.out_hidden.bias[:4] = -8.0
        out = ConeNetExport(net)(x)
        np.testing.assert_allclose(out[0, 4:, 5, 5].numpy(), [2.0, 2.0, 0.5, 0.5], rtol=1e-5)
    path = export_onnx(net, tmp_path / "boxes.onnx", (128, 64))
    assert "hidden-cone heads and boxes" in json.loads(path.with_suffix(".json").read_text())["architecture"]
    assert ConeDetector(path).raw([np.zeros((64, 128, 3), np.uint8)])[0].shape == (1, 8, 32, 64)
    back = load_onnx_weights(ConeNet(stride=2, hidden=True, hidden_boxes=True), path).eval()
    with torch.no_grad():
        np.testing.assert_allclose(ConeNetExport(back)(x).numpy(), ConeNetExport(net)(x).numpy(), atol=1e-5)
    # the box outputs are trained: a loss term of their own, and an error when their targets are missing
    boxes, classes = np.array([[38, 20, 52, 40], [52, 18, 56, 37.]]), np.array([3, 3])
    t = build_targets(boxes, classes, np.zeros(2, bool), (128, 64), 2, np.array([False, True]), True)
    batch = [torch.from_numpy(v)[None] for v in t]
    _, parts = detection_loss(net.train()(x / 255), *batch)
    assert parts["hidden_box"] > 0 and parts["hidden"] > 0
    with pytest.raises(InputError, match="hidden-cone boxes needs their targets"):
        detection_loss(net(x / 255), *batch[:6])


def test_a_deeper_net_starts_as_the_model_it_grows_from_and_its_new_blocks_train(tmp_path):
    from weather_gym.lab.training.detector.conenet import ConeNet, ConeNetExport
    from weather_gym.lab.training.detector.train import detection_loss, export_onnx, load_onnx_weights

    torch.manual_seed(7)
    small = ConeNet(stride=2, hidden=True).eval()
    path = export_onnx(small, tmp_path / "small.onnx", (128, 64))
    assert json.loads(path.with_suffix(".json").read_text())["layout"]["blocks"] == [1, 2, 2, 1]
    deep = load_onnx_weights(ConeNet(stride=2, hidden=True, blocks=(2, 3, 2, 2), stem_blocks=1), path)
    x = torch.rand(1, 3, 64, 128) * 255
    with torch.no_grad():  # the added blocks start as the identity: the same outputs as the file's model
        np.testing.assert_allclose(ConeNetExport(deep.eval())(x).numpy(), ConeNetExport(small)(x).numpy(), atol=1e-5)
    boxes, classes = np.array([[38, 20, 52, 40], [52, 18, 56, 37.]]), np.array([3, 3])
    t = build_targets(boxes, classes, np.zeros(2, bool), (128, 64), 2, np.array([False, True]))
    loss, _ = detection_loss(deep.train()(x / 255), *[torch.from_numpy(v)[None] for v in t])
    loss.backward()
    assert deep.stem_refine[0].pw[1].weight.grad.abs().sum() > 0  # an added block's scale gets a gradient
    assert deep.stages[0][2].pw[1].weight.grad.abs().sum() > 0
    # the deeper model's own file loads back with its layout, and exports what it computes
    grown = export_onnx(deep.eval(), tmp_path / "deep.onnx", (128, 64))
    layout = json.loads(grown.with_suffix(".json").read_text())["layout"]
    assert layout == {"widths": [16, 24, 48, 96, 128], "blocks": [2, 3, 2, 2], "neck": 32, "stem_blocks": 1}
    back = load_onnx_weights(ConeNet(stride=2, hidden=True, blocks=(2, 3, 2, 2), stem_blocks=1), grown).eval()
    with torch.no_grad():
        np.testing.assert_allclose(ConeNetExport(back)(x).numpy(), ConeNetExport(deep)(x).numpy(), atol=1e-5)


@pytest.mark.parametrize("layout, message", [
    (dict(blocks=(1, 1, 2, 1)), "cannot start a net"),  # fewer blocks than the file
    (dict(widths=(16, 32, 48, 96, 128)), "cannot start a net"),  # other widths
    (dict(neck=24), "cannot start a net"),
])
def test_a_net_that_is_not_a_deeper_copy_of_the_start_model_is_a_clear_error(tmp_path, layout, message):
    from weather_gym.lab.training.detector.conenet import ConeNet
    from weather_gym.lab.training.detector.train import export_onnx, load_onnx_weights

    path = export_onnx(ConeNet(stride=2).eval(), tmp_path / "m.onnx", (128, 64))
    with pytest.raises(FileFormatError, match=message):
        load_onnx_weights(ConeNet(stride=2, **layout), path)


@pytest.mark.parametrize("kwargs, message", [
    (dict(blocks=(1, 2, 2)), r"blocks \(--blocks\) must be 4 values, each an integer in \[0, 8\], got \(1, 2, 2\)"),
    (dict(blocks=(1, 2, -1, 1)), r"blocks \(--blocks\) must be 4 values, each an integer in \[0, 8\]"),
    (dict(stem_blocks=-1), r"stem_blocks \(--stem-blocks\) must be an integer in \[0, 8\], got -1"),
    (dict(blocks=(1, 2, 1000, 1)), r"blocks \(--blocks\) must be 4 values, each an integer in \[0, 8\], "
                                   r"got \(1, 2, 1000, 1\)"),
    (dict(stem_blocks=9), r"stem_blocks \(--stem-blocks\) must be an integer in \[0, 8\], got 9"),
])
def test_a_bad_net_layout_is_a_clear_error(kwargs, message):
    with pytest.raises(InputError, match=message):
        TrainConfig(**kwargs)


def test_a_broken_layout_in_a_start_models_sidecar_is_a_clear_error(tmp_path):
    from weather_gym.lab.training.detector.conenet import ConeNet
    from weather_gym.lab.training.detector.train import export_onnx, load_onnx_weights

    path = export_onnx(ConeNet(stride=2).eval(), tmp_path / "m.onnx", (128, 64))
    meta = json.loads(path.with_suffix(".json").read_text())
    path.with_suffix(".json").write_text(json.dumps({**meta, "layout": {"blocks": [1, 2, 2, 1]}}))
    with pytest.raises(FileFormatError, match=r"m\.json: 'layout' must have the keys"):
        load_onnx_weights(ConeNet(stride=2), path)


class _OneFrame:
    """A one-frame data set: a 20 px yellow cone and a 4 px blue one, too small to be scored (iscrowd)."""

    root = "one-frame"

    def __len__(self):
        return 1

    def image(self, i):
        return np.full((288, 512, 3), 100, np.uint8)

    def gt(self, i):
        return {"boxes": np.array([[100, 150, 114, 170], [300, 140, 303, 144.]]), "classes": np.array([1, 0]),
                "iscrowd": np.array([0, 1]), "ranges": np.array([10.0, 40.0])}


@pytest.mark.parametrize("tiny_negatives", [False, True])
def test_tiny_negatives_make_a_tiny_cone_a_negative_for_the_other_classes_only(tiny_negatives):
    from weather_gym.lab.training.detector.train.data import _Frames

    cfg = TrainConfig(crop_size=None, stride=2, hidden=True, tiny_negatives=tiny_negatives)
    _, heat, ign, *_ = _Frames([_OneFrame()], cfg, train=False)[0]
    cell = (71, 150)  # the tiny blue cone's centre on the stride-2 grid
    assert ign.shape == (4, 144, 256) and heat[:, cell[0], cell[1]].max() == 0  # never a positive
    if tiny_negatives:  # ignored in blue only (main and hidden heatmaps share the map); a negative for the rest
        assert ign[0, cell[0], cell[1]] == 1 and (ign[1:, cell[0], cell[1]] == 0).all()
    else:
        assert (ign[:, cell[0], cell[1]] == 1).all()


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


def test_sample_workers_train_the_same_model_as_the_training_process(tmp_path):
    data = write_synth_dataset(tmp_path / "synth", 6, seed=3)
    outs = []
    for workers in (0, 2):
        out = tmp_path / f"w{workers}.onnx"
        train_detector([data], out, TrainConfig(max_steps=3, workers=workers, **SMALL), progress=False,
                       log=lambda *_: None)
        outs.append(ConeDetector(out))
    x = np.random.default_rng(1).random((1, 3, 160, 256), dtype=np.float32) * 255
    a, b = (d.session.run(None, {"images": x})[0] for d in outs)
    np.testing.assert_array_equal(a, b)
    assert "2 sample workers" in json.loads((tmp_path / "w2.json").read_text())["training"]["hardware"]


@pytest.mark.parametrize("device", ["gpu", "cuda:x", "tpu:0"])
def test_a_bad_training_device_is_a_clear_error(device):
    with pytest.raises(InputError, match=r"device \(--device\) must be a string matching"):
        TrainConfig(device=device)


def test_cuda_without_a_gpu_is_a_clear_error(tmp_path):
    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA GPU")
    data = write_synth_dataset(tmp_path / "synth", 2, seed=3)
    with pytest.raises(InputError, match="no CUDA GPU"):
        train_detector([data], tmp_path / "m.onnx", TrainConfig(max_steps=1, device="cuda", **SMALL), progress=False)


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


# ---------------------------------------------------------------------------------------------- mixing
def _kitti_import(tmp_path, n: int = 3, size: tuple[int, int] = (320, 240), seed: int = 4):
    """An imported recording: ``n`` synthetic frames of another size, written as KITTI and imported, with a
    bottom ego mask stored (like ``weather-gym dataset import kitti`` + ``dataset mask --set``)."""
    import cv2
    from cone_synth import synth_frame

    from weather_gym.core.cone_spec import CONE_CLASSES
    from weather_gym.lab.datasets.importers import import_dataset
    from weather_gym.lab.datasets.masks import set_dataset_mask, write_mask

    src = tmp_path / "kitti"
    (src / "images").mkdir(parents=True)
    (src / "labels").mkdir()
    rng = np.random.default_rng(seed)
    names = {"blue": "blue_cone", "yellow": "yellow_cone", "orange": "orange_cone", "big_orange": "large_orange_cone"}
    for i in range(n):
        img, gt = synth_frame(rng, size=size)
        cv2.imwrite(str(src / "images" / f"{i:06d}.png"), img[..., ::-1])
        rows = [f"{names[CONE_CLASSES[c]]} 0 0 0 {b[0]:.1f} {b[1]:.1f} {b[2]:.1f} {b[3]:.1f} 0 0 0 0 0 0 0"
                for b, c in zip(gt["boxes"], gt["classes"], strict=True)]
        (src / "labels" / f"{i:06d}.txt").write_text("\n".join(rows) + "\n")
    out = tmp_path / "imported"
    import_dataset("kitti", src, out, condition="clear")
    mask = np.zeros((size[1], size[0]), bool)
    mask[int(size[1] * 0.8):] = True
    write_mask(tmp_path / "ego.png", mask)
    set_dataset_mask(out, tmp_path / "ego.png")
    return out


def test_mix_draws_each_folders_share_of_every_epoch_seeded(tmp_path):
    from weather_gym.lab.datasets.coco import load_coco
    from weather_gym.lab.training.detector.train.data import _Frames

    a = load_coco(write_synth_dataset(tmp_path / "a", 6, seed=1))
    b = load_coco(_kitti_import(tmp_path, n=2))
    cfg = TrainConfig(mix=(0.25, 0.75), epoch_frames=40, repeat_threshold=None)
    frames = _Frames([a, b], cfg, train=True)
    order = frames.epoch_order(0)
    assert len(order) == 40 and frames.epoch_size() == 40
    assert (frames.source[order] == 0).sum() == 10 and (frames.source[order] == 1).sum() == 30
    assert set(order[frames.source[order] == 0]) == set(range(6))  # without replacement while enough frames
    np.testing.assert_array_equal(order, _Frames([a, b], cfg, train=True).epoch_order(0))  # same seed, same order
    assert not np.array_equal(order, frames.epoch_order(1))
    only_b = _Frames([a, b], TrainConfig(mix=(0.0, 1.0), epoch_frames=8), train=True).epoch_order(0)
    assert (frames.source[only_b] == 1).all()
    with pytest.raises(InputError, match="2 data folders"):
        _Frames([a, b], TrainConfig(mix=(1.0,)), train=True)
    with pytest.raises(InputError, match="mix"):
        TrainConfig(mix=(-1.0, 2.0))


def test_an_imported_set_trains_with_its_ignore_mask_and_regions_as_no_loss(tmp_path):
    from weather_gym.lab.datasets.coco import load_coco
    from weather_gym.lab.training.detector.train.data import _Frames

    ds = load_coco(_kitti_import(tmp_path, n=1))
    assert ds.image(0).shape == (240, 320, 3)
    frames = _Frames([ds], TrainConfig(crop_size=None), train=False)
    x, heat, ign, *_ = frames[0]
    assert tuple(x.shape) == (3, 288, 512)
    # 320x240 letterboxed into 512x288: scale 1.2, 64 px bars left and right; the mask is the bottom 20 %
    assert ign[:, -3:, 20:100].min() == 1.0 and ign[:, : int(72 * 0.7), 20:100].sum() == 0  # every class
    assert ign[:, :, :10].max() == 0.0  # the letterbox bars are plain negatives


@pytest.mark.slow
def test_cli_trains_on_a_rendered_and_an_imported_set_mixed(tmp_path, capsys):
    from weather_gym.cli import main

    a = write_synth_dataset(tmp_path / "a", 3, seed=1)
    b = _kitti_import(tmp_path, n=2)
    out = tmp_path / "m.onnx"
    assert main(["detector", "train", "--data", str(a), "--data", str(b), "--mix", "0.5,0.5", "--epoch-frames", "4",
                 "--epochs", "1", "--batch-size", "2", "--input-size", "256", "160", "--crop-size", "128", "96",
                 "--recipe", "real", "--stride", "2", "--hidden-heads", "--blocks", "1,2,3,1", "--stem-blocks", "1",
                 "--out", str(out)]) == 0
    meta = json.loads(out.with_suffix(".json").read_text())
    cfg = meta["training"]["config"]
    assert cfg["mix"] == [0.5, 0.5] and cfg["distractors"] > 0 and meta["training"]["steps"] == 2
    assert meta["training"]["frames_per_data"] == [3, 2]
    assert cfg["hidden"] and cfg["stride"] == 2 and "hidden-cone" in meta["architecture"]
    assert meta["layout"]["blocks"] == [1, 2, 3, 1] and meta["layout"]["stem_blocks"] == 1
    capsys.readouterr()
    assert main(["detector", "train", "--data", str(a), "--blocks", "1,2,x,1", "--out", str(tmp_path / "n.onnx")]) == 2
    assert "--blocks must be 4 comma-separated whole numbers" in capsys.readouterr().err


def test_a_shipped_onnx_model_loads_back_into_torch(tmp_path):
    from weather_gym.lab.training.detector.conenet import ConeNet, ConeNetExport
    from weather_gym.lab.training.detector.train import export_onnx, load_onnx_weights

    torch.manual_seed(3)
    net = ConeNet()
    for m in net.modules():  # non-trivial batch-norm statistics, so that folding matters
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
            m.bias.data.uniform_(-0.2, 0.2)
    path = export_onnx(net.eval(), tmp_path / "m.onnx", (128, 64))
    back = load_onnx_weights(ConeNet(), path).eval()
    x = torch.rand(1, 3, 64, 128) * 255
    with torch.no_grad():
        np.testing.assert_allclose(ConeNetExport(back)(x).numpy(), ConeNetExport(net)(x).numpy(), atol=1e-4)
    with pytest.raises(FileFormatError):
        (tmp_path / "bad.onnx").write_bytes(b"not onnx")
        load_onnx_weights(ConeNet(), tmp_path / "bad.onnx")


def test_clear_day_camera_look_never_darkens_much_but_the_degrading_one_does():
    from weather_gym.perception.augment import camera_look

    img = np.full((64, 64, 3), 90, np.uint8)
    img[20:44, 28:36] = (30, 60, 200)
    clear = [camera_look(img, np.random.default_rng(s)).mean() for s in range(40)]
    degraded = [camera_look(img, np.random.default_rng(s), degrade=True).mean() for s in range(40)]
    assert min(clear) > 0.7 * img.mean() and max(clear) > 1.4 * img.mean()  # normal up to blown-out
    assert min(degraded) < 0.55 * img.mean()  # the degrading look also under-exposes (as dimming does)


def test_real_recipe_augments_with_clutter_and_camera_looks_but_keeps_the_boxes():
    img = np.full((376, 672, 3), 100, np.uint8)
    img[200:260, 300:340] = (30, 60, 200)
    box = np.array([[300, 200, 340, 260.]])
    cfg = TrainConfig.recipe("real", crop_size=None)
    assert cfg.distractors > 0 and cfg.camera > 0 and cfg.scale_range[1] > 2
    changed = 0
    for seed in range(6):
        out, b, vis = augment(img, box, cfg, np.random.default_rng(seed))
        plain, *_ = augment(img, box, TrainConfig(crop_size=None), np.random.default_rng(seed))
        changed += int(not np.array_equal(out, plain))
        np.testing.assert_array_equal(augment(img, box, cfg, np.random.default_rng(seed))[0], out)  # seeded
    assert changed >= 4
    assert not cfg.camera_degrade and TrainConfig.recipe("real_robust").camera_degrade
    with pytest.raises(InputError, match="recipe"):
        TrainConfig.recipe("nosuch")
