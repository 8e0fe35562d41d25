"""The parts of the gap workflow: image signals, perception statistics, statistics, model files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from weather_gym.lab.gap.compare import GapMeter, compare_signals, gap_test, holm, signal_scale
from weather_gym.lab.gap.signals import SIGNAL_NAMES, SIGNALS, frame_signals, signal_weights
from weather_gym.lab.gap.simulate import split_indices
from weather_gym.lab.gap.weather_model import (
    CHAIN_ORDER,
    apply_chain,
    insert_position,
    model_tables,
    read_model,
    write_model,
)
from weather_gym.weather import EFFECTS, make


@pytest.fixture(scope="module")
def frames(clean_dir):
    from weather_gym.lab.datasets import load_coco

    ds = load_coco(clean_dir)
    return [(ds.image(i), ds.depth(i), ds.gt(i)["boxes"], ds.record(i)) for i in range(0, len(ds), 4)]


def _signals(frames, effect=None):
    out = []
    for img, depth, boxes, rec in frames:
        if effect is not None:
            img = apply_chain([effect], img, depth=depth, state={"speed": rec["speed"]}, seed=0, frame_id=rec["id"])
        out.append(frame_signals(img, depth, boxes))
    return np.array(out)


def _mean(table, name):
    return float(np.nanmean(table[:, SIGNAL_NAMES.index(name)]))


@pytest.mark.slow
def test_each_effect_moves_its_own_signals(frames):
    clean = _signals(frames)
    moved = {name: _signals(frames, make(name, k=k)) - clean for name, k in
             (("blur", 0.6), ("dim", 0.5), ("noise", 0.4), ("jpeg", 0.8), ("vignette", 0.7), ("fog", 0.6))}

    def shift(name, signal):
        return float(np.nanmean(moved[name][:, SIGNAL_NAMES.index(signal)]))

    assert shift("blur", "sharp_fine") < -0.3 and abs(shift("blur", "brightness")) < 1.0
    assert shift("dim", "brightness") < -20
    for s in ("sharp_fine", "sharp_half", "edge_p99", "blockiness", "vignette", "haze_lift"):
        assert abs(shift("dim", s)) < 0.1, s  # a global gain does not move the contrast-normalised signals
    assert shift("noise", "noise_flat") > 0.5
    assert shift("jpeg", "blockiness") > 0.1 and shift("jpeg", "block_chroma") > 0.05
    assert shift("vignette", "vignette") < -0.1
    assert shift("fog", "haze_lift") > 0.1 and shift("fog", "saturation") < -0.05


def test_signals_validate_their_input():
    with pytest.raises(ValueError, match="RGB uint8"):
        frame_signals(np.zeros((40, 40), np.uint8))
    with pytest.raises(ValueError, match="too small"):
        frame_signals(np.zeros((8, 8, 3), np.uint8))
    v = frame_signals(np.full((64, 96, 3), 100, np.uint8))
    assert math.isnan(v[SIGNAL_NAMES.index("cone_contrast")])  # no boxes, no cone signal


def test_every_family_weighs_the_same():
    w = signal_weights()
    fam = {}
    for s, x in zip(SIGNALS, w):
        fam[s.family] = fam.get(s.family, 0.0) + x
    assert all(v == pytest.approx(1.0) for v in fam.values())


def test_gap_meter_paired_and_unpaired():
    rng = np.random.default_rng(0)
    meas = rng.normal(size=(30, len(SIGNALS)))
    scale = signal_scale(meas)
    paired = GapMeter(meas, scale=scale, weights=signal_weights(), paired=True)
    assert paired.gap(meas) == 0.0
    shifted = meas + 2.0 * scale
    assert paired.gap(shifted) == pytest.approx(2.0)
    assert float(np.linalg.norm(paired.residuals(shifted))) == pytest.approx(2.0)
    unpaired = GapMeter(meas, scale=scale, weights=signal_weights(), paired=False)
    other = rng.normal(size=(40, len(SIGNALS)))
    assert unpaired.gap(other) < 0.6  # same distribution, other frames: a small gap
    assert unpaired.gap(other + 3.0 * scale) > 2.4


def test_noise_is_not_reported_as_a_disagreement():
    rng = np.random.default_rng(1)
    meas = rng.normal(size=(40, len(SIGNALS)))
    meter = GapMeter(meas, scale=np.ones(len(SIGNALS)), weights=signal_weights(), paired=True)
    same = meas + rng.normal(scale=0.3, size=meas.shape)  # per-frame noise, no bias
    assert not any(r["significant"] for r in compare_signals(meter, same, b=400))
    biased = same.copy()
    biased[:, 3] += 1.0
    rows = compare_signals(meter, biased, b=400)
    assert [r["signal"] for r in rows if r["significant"]] == [SIGNAL_NAMES[3]]
    t = gap_test(meter, biased, same, b=400)
    assert t["reduction"] > 0 and t["p_value"] < 0.01


def test_holm():
    assert holm(np.array([0.001, 0.03, 0.04]), 0.05).tolist() == [True, False, False]
    assert holm(np.array([0.001, 0.012, 0.03]), 0.05).tolist() == [True, True, True]
    assert holm(np.array([np.nan, 0.0]), 0.05).tolist() == [False, True]


@pytest.mark.slow
def test_bootstrappable_map_equals_pycocotools(clean_dir):
    from weather_gym.lab.datasets import load_coco
    from weather_gym.lab.gap.perception import detect_frames, match_frames, perception_stats
    from weather_gym.perception import ConeDetector, evaluate

    ds = load_coco(clean_dir)
    det = ConeDetector(threads=1)
    gts = [ds.gt(i) for i in range(len(ds))]
    for effect in (None, make("blur", k=0.8), make("dim", k=0.7)):
        ims = [ds.image(i) if effect is None else effect(ds.image(i)) for i in range(len(ds))]
        dets = detect_frames(det, ims)
        ref = evaluate(gts, dets, score_threshold=det.score_threshold)
        stats = perception_stats(match_frames(gts, dets, score_threshold=det.score_threshold))
        assert stats["map50"] == pytest.approx(ref.map50, abs=1e-12)
        for name, ap in ref.ap50_per_class.items():
            assert (math.isnan(ap) and math.isnan(stats[f"ap50.{name}"])) or stats[f"ap50.{name}"] == pytest.approx(ap)
        assert stats["recall"] == pytest.approx(ref.recall)


def test_model_file_round_trip(tmp_path):
    effects = [make("fog", k=0.3, airlight=0.7), make("exposure", k=0.25, direction="over"), make("noise", k=0.1)]
    path = tmp_path / "m.toml"
    write_model(path, effects, {1: "a comment"}, header="a header")
    back = read_model(path)
    assert [e.params() for e in back] == [e.params() for e in effects]
    assert model_tables(back)[1] == {"name": "exposure", "k": 0.25, "direction": "over"}
    write_model(path, [], overwrite=True)
    assert read_model(path) == []
    (tmp_path / "empty.toml").write_text("")
    assert read_model(tmp_path / "empty.toml") == []


def test_model_file_errors_name_the_file(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text('[[effects]]\nname = "dim"\nk = 0.2\n[[effects]]\nname = "dim"\nk = 0.3\n')
    with pytest.raises(ValueError, match=f"{p}.*appears twice"):
        read_model(p)
    with pytest.raises(FileNotFoundError, match="not found"):
        read_model(tmp_path / "nope.toml")


def test_chain_order_and_insertion():
    assert set(CHAIN_ORDER) == set(EFFECTS.names())
    model = [make("dim", k=0.3), make("jpeg", k=0.5)]
    assert insert_position(model, "noise") == 1
    assert insert_position(model, "blur") == 0
    assert insert_position(model, "fog") == 0
    assert insert_position([], "jpeg") == 0


def test_common_random_numbers():
    img = np.full((40, 60, 3), 120, np.uint8)
    a = apply_chain([make("noise", k=0.5)], img, depth=None, state=None, seed=3, frame_id=7)
    b = apply_chain([make("noise", k=0.5)], img, depth=None, state=None, seed=3, frame_id=7)
    c = apply_chain([make("noise", k=0.5)], img, depth=None, state=None, seed=3, frame_id=8)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_split_is_seeded_and_disjoint():
    f1, h1 = split_indices(20, held_out=0.5, seed=2)
    f2, h2 = split_indices(20, held_out=0.5, seed=2)
    assert f1.tolist() == f2.tolist() and h1.tolist() == h2.tolist()
    assert not set(f1) & set(h1) and len(f1) + len(h1) == 20
    with pytest.raises(ValueError, match="at least 4 frames"):
        split_indices(3)
