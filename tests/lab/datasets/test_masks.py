"""Ignore masks: proposed from the frames, stored with the dataset, applied wherever frames are scored."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.cli import main
from weather_gym.lab.datasets.coco import CocoWriter, load_coco
from weather_gym.lab.datasets.masks import propose_mask, read_mask, set_dataset_mask, write_mask
from weather_gym.perception.scoring import evaluate

H, W = 90, 120


def _moving_frames(n=8, seed=0):
    """A scene that moves (random texture shifting) above a static 'bonnet' in the lower third, and a
    static, saturated 'sky' band at the top."""
    rng = np.random.default_rng(seed)
    world = rng.integers(0, 256, (H, W * 3, 3), dtype=np.uint8)
    frames = []
    for i in range(n):
        f = world[:, i * 20:i * 20 + W].copy()
        f[:12] = 255                     # over-exposed sky: static too, but not the car
        f[60:] = 70
        f[60:, 40:80] = (200, 30, 30)    # the car's nose
        frames.append(f)
    return frames


def test_proposal_finds_the_static_car_not_the_static_sky():
    m = propose_mask(_moving_frames())
    assert m[62:].mean() > 0.97
    assert m[:12].mean() == 0.0 and m[15:55].mean() < 0.02


def test_proposal_needs_a_moving_scene():
    frames = [np.full((H, W, 3), 100, np.uint8)] * 6
    with pytest.raises(ValueError, match="hardly change"):
        propose_mask(frames)
    with pytest.raises(ValueError, match="at least 4 frames"):
        propose_mask(frames[:3])


def _dataset(root, frames):
    with CocoWriter(root) as w:
        for f in frames:
            # a cone on the scene, and one on the bonnet (a reflection labelled by a careless labeller)
            w.add(f, {}, {"boxes": np.array([[10, 20, 20, 45], [50, 65, 60, 85.]]), "classes": np.array([0, 1])})
    return root


def test_stored_mask_is_applied_when_scoring(tmp_path):
    root = _dataset(tmp_path / "d", _moving_frames(4))
    mask = np.zeros((H, W), bool)
    mask[60:] = True
    write_mask(tmp_path / "m.png", mask)
    set_dataset_mask(root, tmp_path / "m.png")
    ds = load_coco(root)
    np.testing.assert_array_equal(ds.ignore_mask(0), mask)
    gt = ds.gt(0)
    assert "ignore_mask" in gt
    # a hit on the scene cone, a false positive on the bodywork: the mask drops the latter, and the
    # bonnet cone is ignored rather than missed
    det = {"boxes": np.array([[10, 20, 20, 45], [90, 70, 100, 88.]]), "scores": np.array([0.9, 0.95]),
           "classes": np.array([0, 0])}
    with_mask = evaluate([gt] * 2, [det] * 2)
    assert with_mask.map50 == pytest.approx(1.0) and with_mask.ignored["masked"] == 2
    no_mask = evaluate([{k: v for k, v in gt.items() if k != "ignore_mask"}] * 2, [det] * 2)
    assert no_mask.map50 < 0.6
    assert "2 in the ignore mask" in with_mask.table()


def test_mask_errors_name_the_file(tmp_path):
    root = _dataset(tmp_path / "d", _moving_frames(4))
    write_mask(tmp_path / "small.png", np.zeros((10, 10), bool))
    with pytest.raises(ValueError, match=r"small.png is 10x10 but the frames are 120x90"):
        set_dataset_mask(root, tmp_path / "small.png")
    write_mask(tmp_path / "ok.png", np.zeros((H, W), bool))
    set_dataset_mask(root, tmp_path / "ok.png")
    with pytest.raises(FileExistsError, match="already has an ignore mask"):
        set_dataset_mask(root, tmp_path / "ok.png")
    set_dataset_mask(root, tmp_path / "ok.png", frame="images/000001.png")
    assert load_coco(root).record(1)["ignore_mask"] == "masks/000001.png"
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="junk.png could not be decoded"):
        read_mask(tmp_path / "junk.png")


def test_cli_proposes_an_editable_png_and_stores_it(tmp_path, capsys):
    root = _dataset(tmp_path / "d", _moving_frames(8))
    out = tmp_path / "proposal.png"
    assert main(["dataset", "mask", str(root), "--out", str(out), "--preview", str(tmp_path / "p.png")]) == 0
    m = read_mask(out, (W, H))
    assert m[62:].mean() > 0.97 and (tmp_path / "p.png").is_file()
    assert not (root / "ignore_mask.png").exists()  # a proposal writes only --out
    assert main(["dataset", "mask", str(root), "--set", str(out)]) == 0
    assert load_coco(root).has_ignore_mask
    capsys.readouterr()
    assert main(["dataset", "info", str(root)]) == 0
    assert "ignore mask: ignore_mask.png" in capsys.readouterr().out


@pytest.mark.slow
def test_real_frames_mask_covers_the_car_and_spares_the_track(real_dataset):
    ds = load_coco(real_dataset)
    m = ds.ignore_mask(0)
    h = m.shape[0]
    assert m[int(0.9 * h):].mean() > 0.9          # the car's nose, wheels and steering wheel
    assert m[:int(0.5 * h)].mean() < 0.02         # the track, the cones and the over-exposed sky
    assert 0.2 < m.mean() < 0.5
