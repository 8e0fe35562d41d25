"""The surrogate fit recovers known parameters from synthetic logs; model files are validated on load."""

from __future__ import annotations

import json

import numpy as np
import pytest

from weather_gym.errors import FileFormatError, InputError, MissingInputError
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
        back.point("fog@2")


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
