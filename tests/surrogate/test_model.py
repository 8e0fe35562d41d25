"""The surrogate fit recovers known parameters from synthetic logs; model files are validated on load."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.surrogate.log import SurrogateLog
from weather_gym.surrogate.model import SHIPPED_MODEL, fit, load_model, save_model

FY = 336.0
TRUE_RHO = 0.6
FP_RATE = 1.5


def _p_true(r):
    return 1.0 / (1.0 + np.exp(-(3.0 - 0.2 * r)))


def synthetic_log(seed: int = 0, frames: int = 400, cones: int = 30, condition=("clear", 0.0)) -> SurrogateLog:
    """Cones at fixed ranges 2-40 m, detected by a Markov chain with marginal ``_p_true`` and
    persistence ``TRUE_RHO``; Poisson(``FP_RATE``) false positives far from every cone."""
    rng = np.random.default_rng(seed)
    r = np.linspace(2.0, 40.0, cones)
    p = _p_true(r)
    h = FY * 0.325 / r
    det = np.zeros((frames, cones), bool)
    det[0] = rng.random(cones) < p
    for t in range(1, frames):
        q = np.where(det[t - 1], p + TRUE_RHO * (1 - p), p * (1 - TRUE_RHO))
        det[t] = rng.random(cones) < q
    f_idx, c_idx = np.meshgrid(np.arange(frames), np.arange(cones), indexing="ij")
    f_idx, c_idx = f_idx.ravel(), c_idx.ravel()
    n = len(f_idx)
    x = 60.0 * c_idx  # apart: no crowding
    box = np.column_stack([x, 200 - h[c_idx], x + 0.7 * h[c_idx], np.full(n, 200.0)]).astype(np.float32)
    y = det.ravel()
    c = {"episode": np.zeros(n, np.int32), "frame": f_idx.astype(np.int32), "cone_id": c_idx.astype(np.int32),
         "cls": np.ones(n, np.int8), "range": r[c_idx].astype(np.float32), "bearing": np.zeros(n, np.float32),
         "box": box, "box_h": h[c_idx].astype(np.float32), "pixels": np.full(n, 100, np.int32),
         "visibility": np.ones(n, np.float32), "speed": np.full(n, 5, np.float32), "yaw_rate": np.zeros(n, np.float32),
         "detected": y, "det_cls": np.where(y, 1, -1).astype(np.int8), "det_score": np.where(y, 0.8, np.nan).astype(np.float32),
         "range_err": np.where(y, rng.normal(0.0, 0.1, n), np.nan).astype(np.float32),
         "bearing_err": np.where(y, 0.0, np.nan).astype(np.float32)}
    n_fp = rng.poisson(FP_RATE, frames)
    m = int(n_fp.sum())
    fps = {"episode": np.zeros(m, np.int32), "frame": np.repeat(np.arange(frames), n_fp).astype(np.int32),
           "range": rng.uniform(5, 30, m).astype(np.float32), "bearing": rng.uniform(-0.5, 0.5, m).astype(np.float32),
           "cls": rng.integers(0, 2, m).astype(np.int8), "score": rng.uniform(0.3, 0.6, m).astype(np.float32),
           "box": np.tile(np.array([[1900, 10, 1905, 15]], np.float32), (m, 1))}
    fr = {"episode": np.zeros(frames, np.int32), "frame": np.arange(frames, dtype=np.int32),
          "n_gt": np.full(frames, cones, np.int32), "n_fp": n_fp.astype(np.int32),
          "speed": np.full(frames, 5, np.float32), "yaw_rate": np.zeros(frames, np.float32)}
    from weather_gym.weather import current_spec, parse_weather

    weather = current_spec(parse_weather({condition[0]: condition[1]})) if condition[0] != "clear" else []
    eps = [{"track": "synthetic", "weather": weather, "condition": condition[0], "k": condition[1], "seed": seed}]
    return SurrogateLog(c, fps, fr, eps, {"camera": {"width": 672, "height": 376}})


@pytest.fixture(scope="module")
def fitted():
    return fit(synthetic_log())


def test_fit_recovers_detection_curve_persistence_and_fp_rate(fitted):
    p = fitted.clear
    r = np.array([4.0, 10.0, 15.0, 25.0, 35.0])
    got = p.detection_probability(r, np.zeros(5), FY * 0.325 / r, np.ones(5), np.ones(5, np.int64))
    np.testing.assert_allclose(got, _p_true(r), atol=0.05)
    assert abs(p.rho - TRUE_RHO) < 0.06
    assert abs(p.fp_mean - FP_RATE) < 0.15
    assert p.stats["p_miss_after_miss"] > p.stats["p_miss_after_detected"] + 0.3
    np.testing.assert_allclose(p.range_err_q[1, [10, 20, 30]], [-0.067, 0.0, 0.067], atol=0.03)
    assert p.confusion[1, 1, 1] > 0.95


def test_save_load_round_trip_and_interpolation(tmp_path):
    log = synthetic_log(condition=("clear", 0.0))
    wet = synthetic_log(seed=1, condition=("droplets", 0.4))
    wet.cones["detected"][:] = False  # a weather in which nothing is detected
    from weather_gym.surrogate.log import concat_logs

    model = fit(concat_logs([log, wet]))
    path = save_model(model, tmp_path / "m.npz")
    back = load_model(path)
    assert back.conditions() == ["clear", "droplets"]
    r = np.array([5.0])
    args = (r, np.zeros(1), FY * 0.325 / r, np.ones(1), np.ones(1, np.int64))
    p0 = back.point("clear").detection_probability(*args)[0]
    p_half = back.point({"droplets": 0.2}).detection_probability(*args)[0]
    p1 = back.point({"droplets": 0.4}).detection_probability(*args)[0]
    assert p0 > 0.8 and p1 < 0.05 and p1 < p_half < p0
    with pytest.raises(InputError, match="beyond"):
        back.point({"droplets": 0.6})
    with pytest.raises(InputError, match="no model of weather effect 'fog'"):
        back.point("fog@2")  # the model itself is strict; the wrapper falls back (resolve)
    point, note = back.resolve("fog@2")
    assert point is back.clear and "no fit of weather effect fog (k 0.5)" in note
    point, note = back.resolve({"droplets": 0.2})
    assert note is None and point.detection_probability(*args)[0] == p_half


def _broken(tmp_path, name, edit):
    with np.load(SHIPPED_MODEL) as z:
        data = {k: z[k] for k in z.files}
    edit(data)
    path = tmp_path / name
    np.savez(path, **data)
    return path


@pytest.mark.parametrize("name, edit, match", [
    ("nometa.npz", lambda d: d.pop("meta"), "no 'meta'"),
    ("schema.npz", lambda d: d.update(meta=np.array(json.dumps({**json.loads(str(d["meta"])), "schema": 99}))),
     "schema 99"),
    ("conf.npz", lambda d: d.update({"clear/confusion": d["clear/confusion"] * 2}), "summing to 1"),
    ("shape.npz", lambda d: d.update({"clear/coef": d["clear/coef"][:3]}), "clear/coef"),
    ("nan.npz", lambda d: d.update({"clear/score_q": d["clear/score_q"] * np.nan}), "non-finite"),
    ("missing.npz", lambda d: d.pop("clear/fp_rows"), "missing array 'clear/fp_rows'"),
])
def test_bad_model_file_is_a_typed_error(tmp_path, name, edit, match):
    with pytest.raises(FileFormatError, match=match):
        load_model(_broken(tmp_path, name, edit))


def test_not_a_model_file(tmp_path):
    (tmp_path / "x.npz").write_bytes(b"not a zip")
    with pytest.raises(FileFormatError, match="not a readable"):
        load_model(tmp_path / "x.npz")
    with pytest.raises(MissingInputError):
        load_model(tmp_path / "absent.npz")


def test_shipped_model_covers_every_calibrated_preset():
    m = load_model()
    for cond in ("droplets", "low_light"):
        for s in (1, 2, 3, 4):
            p = m.point(f"{cond}@{s}")
            assert 0.0 <= p.rho < 1.0
    assert m.camera_size == (672, 376)


@pytest.mark.parametrize("empty", ["a", "b"])
def test_between_two_points_one_without_false_positives_draws_the_others(empty):
    # a weather between two fitted severities, one of which logged no false positive (it crashed before)
    from dataclasses import replace

    from weather_gym.surrogate.model import _mix
    from weather_gym.surrogate.sample import FrameSampler

    model = load_model(SHIPPED_MODEL)
    a, b = model.point("clear"), model.point("clear")
    none = np.zeros((0, a.fp_rows.shape[1]))
    a, b = (replace(a, fp_rows=none), b) if empty == "a" else (a, replace(b, fp_rows=none))
    mixed = _mix(a, b, 0.5)
    rows = FrameSampler(mixed)._fp_rows(np.random.default_rng(0), 500)
    assert rows.shape == (500, a.fp_rows.shape[1]) and len(mixed.fp_rows) > 0


def test_part_detections_belong_to_their_cone_and_scale_with_the_cones_in_view():
    """A box on a near cone's stripe is a false positive that belongs to that cone: the fit learns how
    often each kind of cone carries one, and the sampler draws them on the cones of the frame (so a
    track with fewer near cones gets fewer), placed relative to the cone's box."""
    from weather_gym.surrogate.log import loose_matches, part_matches
    from weather_gym.surrogate.sample import FrameSampler

    log = synthetic_log(frames=300, seed=2)
    c, f = log.cones, log.fps
    rng = np.random.default_rng(1)
    near = np.flatnonzero((c["range"] < 8) & (rng.random(len(c["range"])) < 0.5))  # half the near cones, each frame
    b = c["box"][near]
    h = b[:, 3] - b[:, 1]
    stripe = np.column_stack([b[:, 0] + 0.3 * (b[:, 2] - b[:, 0]), b[:, 1] + 0.4 * h, b[:, 2] - 0.3 * (b[:, 2] - b[:, 0]),
                              b[:, 1] + 0.5 * h]).astype(np.float32)
    for key, extra in (("episode", c["episode"][near]), ("frame", c["frame"][near]), ("range", c["range"][near]),
                       ("bearing", c["bearing"][near]), ("cls", np.full(len(near), 2, np.int8)),
                       ("score", np.full(len(near), 0.35, np.float32)), ("box", stripe)):
        f[key] = np.concatenate([f[key], extra])
    order = np.lexsort((f["frame"], f["episode"]))
    for key in f:
        f[key] = f[key][order]
    log.frames["n_fp"] += np.bincount(c["frame"][near], minlength=len(log.frames["n_fp"])).astype(np.int32)
    lm = loose_matches(log)
    pm = part_matches(log, lm)
    is_stripe = f["score"] == np.float32(0.35)
    assert (pm[is_stripe] >= 0).all() and (pm[~is_stripe] < 0).all()  # the Poisson ones sit off every cone
    np.testing.assert_array_equal(np.sort(pm[is_stripe]), np.sort(near))

    p = fit(log).clear
    r = np.array([3.0, 6.0, 30.0])
    got = p.probability_of(p.features(r, np.zeros(3), FY * 0.325 / r, np.ones(3)), np.ones(3, np.int64), kind="part")
    assert abs(got[0] - 0.5) < 0.12 and abs(got[1] - 0.5) < 0.12 and got[2] < 0.05
    assert abs(p.fp_mean - FP_RATE) < 0.15  # the cone-free ones alone
    np.testing.assert_allclose(p.part_rows[:, :4].mean(axis=0), [0.3 * 0.7, 0.4, -0.3 * 0.7, -0.5], atol=0.02)

    point = dataclasses.replace(p, fp_mean=0.0, fp_var=0.0)
    sampler = FrameSampler(point)

    def parts(ranges):
        n = len(ranges)
        hh = FY * 0.325 / ranges
        boxes = np.column_stack([80.0 * np.arange(n), 200 - hh, 80.0 * np.arange(n) + 0.7 * hh, np.full(n, 200.0)])
        gt = {"boxes": boxes, "classes": np.ones(n, np.int64), "cone_ids": np.arange(n), "ranges": ranges,
              "bearings": np.zeros(n)}
        r_ = np.random.default_rng(0)
        return np.mean([np.sum(sampler(gt, r_, step=t)["classes"] == 2) for t in range(0, 600, 2)])

    assert parts(np.full(6, 30.0)) < 0.1
    assert abs(parts(np.full(6, 4.0)) - 3.0) < 0.5


def test_crowded_cones_get_their_own_class_confusion():
    """A cone partly behind another is reported in the wrong class far more often (start-line pairs):
    the fit keeps a confusion for crowded cones, and the sampler uses it for overlapping boxes."""
    from weather_gym.surrogate.sample import FrameSampler

    log = synthetic_log(frames=200)
    c = log.cones
    pair = c["cone_id"] % 2 == 1  # every odd cone stands half behind the even one before it
    c["box"][pair, 0] -= 55.0
    c["box"][pair, 2] -= 55.0
    wrong = pair & c["detected"] & (c["range"] < 15)
    c["det_cls"][wrong] = 0
    p = fit(log).clear
    assert p.confusion_crowded[1, 1, 0] > 0.4 and p.confusion[1, 1, 0] < 0.05  # half the crowded: the rear cones

    point = dataclasses.replace(load_model().point("clear"), coef=np.r_[20.0, np.zeros(len(p.coef) - 1)],
                                confusion=np.tile(np.eye(4), (6, 1, 1)), confusion_crowded=np.tile(np.eye(4)[[2, 2, 2, 2]], (6, 1, 1)))
    gt = {"boxes": np.array([[100, 150, 130, 200], [110, 150, 140, 200], [400, 150, 430, 200.]]),
          "classes": np.array([1, 1, 1]), "cone_ids": np.arange(3), "ranges": np.full(3, 6.0), "bearings": np.zeros(3)}
    point.fp_mean = 0.0
    point.coef_part = np.r_[-20.0, np.zeros(len(p.coef) - 1)]
    det = FrameSampler(point)(gt, np.random.default_rng(0), step=0)
    assert sorted(det["classes"].tolist()) == [1, 2, 2]


def test_a_parameter_added_after_the_fit_counts_at_its_default():
    m = load_model()
    old = {k: v for k, v in m.effects["droplets"].items() if k not in ("mode", "drop_count")}
    m = dataclasses.replace(m, effects={**m.effects, "droplets": old})  # fitted before they existed
    assert m.point("droplets:0.5:mode=faithful").rho == m.point("droplets:0.5").rho
    with pytest.raises(InputError, match="mode='faithful', given 'refractive'"):
        m.point("droplets:0.5:mode=refractive")
    with pytest.raises(InputError, match="fog_coef=0.4, given 0.3"):
        m.point("droplets:0.5:fog_coef=0.3")
