"""The surrogate's per-frame sampler: crowding, and frames of any size (none, one, hundreds of cones)."""

from __future__ import annotations

import numpy as np

from weather_gym.surrogate.log import _iou_matrix
from weather_gym.surrogate.model import SHIPPED_MODEL, crowding, load_model
from weather_gym.surrogate.sample import FrameSampler


def test_crowding_is_each_boxs_largest_iou_with_another():
    rng = np.random.default_rng(0)
    for n in (2, 3, 20, 60):
        xy = rng.uniform(0, 80, (n, 2))
        boxes = np.hstack([xy, xy + rng.exponential(15, (n, 2))])
        boxes[0] = boxes[1]  # identical boxes: IoU 1
        boxes[-1, 2:] = boxes[-1, :2]  # an empty box
        iou = _iou_matrix(boxes, boxes)
        np.fill_diagonal(iou, 0.0)
        np.testing.assert_array_equal(crowding(boxes), iou.max(axis=1))
    assert crowding(np.zeros((1, 4))).tolist() == [0.0] and crowding(np.zeros((0, 4))).shape == (0,)


def _frame(rng: np.random.Generator, n: int, first_id: int = 0) -> dict[str, np.ndarray]:
    r = rng.uniform(2.0, 40.0, n)
    h = 336 * 0.325 / r
    x = rng.uniform(0, 672, n)
    return {"boxes": np.column_stack([x - 0.35 * h, 200 - h, x + 0.35 * h, np.full(n, 200.0)]).astype(np.float32),
            "classes": rng.integers(0, 4, n), "cone_ids": first_id + np.arange(n), "ranges": r.astype(np.float32),
            "bearings": rng.uniform(-0.7, 0.7, n).astype(np.float32)}


def test_frames_of_any_size_same_seed_same_bytes():
    model = load_model(SHIPPED_MODEL)
    frames = [_frame(np.random.default_rng(i), n, first_id)
              for i, (n, first_id) in enumerate([(0, 0), (1, 3), (300, 0), (300, 0), (20, 900), (2, 5)])]

    def run() -> list[dict[str, np.ndarray]]:
        sampler, rng = FrameSampler(model.point("droplets@3")), np.random.default_rng(7)
        return [sampler(gt, rng, step) for step, gt in enumerate(frames)]

    a, b = run(), run()
    for da, db in zip(a, b, strict=True):
        assert sorted(da) == ["bearings", "boxes", "classes", "ranges", "scores"]
        m = len(da["classes"])
        assert da["boxes"].shape == (m, 4) and all(da[k].shape == (m,) for k in ("scores", "ranges", "bearings"))
        assert all(np.array_equal(da[k], db[k]) and da[k].dtype == db[k].dtype for k in da)
    assert len(a[2]["classes"]) > 50  # hundreds of cones in view, near ones mostly detected


def test_the_samplers_probabilities_are_the_models():
    """The sampler computes the three probability models at once for speed; they must stay Point.probability_of."""
    from weather_gym.surrogate.sample import _Tables

    model = load_model(SHIPPED_MODEL)
    rng = np.random.default_rng(3)
    for weather in ("clear", "droplets@3", "low_light@1"):
        point = model.point(weather)
        tables = _Tables(point)
        for n, with_crowd in ((1, False), (40, True), (300, True)):
            cls = rng.integers(0, 4, n)
            box_h = rng.uniform(0.5, 80.0, n)
            crowd = rng.uniform(0.0, 1.0, n) if with_crowd else None
            feats = point.features(rng.uniform(1.0, 60.0, n), rng.uniform(-0.8, 0.8, n), box_h,
                                   rng.uniform(0.0, 1.0, n), crowd)
            got = tables.probabilities(feats, cls)
            for row, kind in enumerate(("detected", "loose", "part")):
                np.testing.assert_array_equal(got[row], point.probability_of(feats, cls, kind=kind))


GOLDEN_672 = "a77ef56e11d95532704df55d8e5c9548d2264575e123a04006adc967b78f8df7"
"""sha256 of 150 surrogate steps at 672x376 in clear, droplets@3 and low_light@1 (seed 5): the shipped
model's samples at its fitting camera, recorded before the camera-size scaling; they must not change."""


def test_the_fitting_cameras_samples_are_unchanged():
    import hashlib

    from weather_gym.pipeline import make_env

    h = hashlib.sha256()
    for weather in ("clear", "droplets@3", "low_light@1"):
        env = make_env(perception="surrogate", weather=weather, max_episode_steps=200)
        try:
            obs, info = env.reset(seed=5)
            for _ in range(150):
                obs, _, term, trunc, info = env.step(np.array([0.3, 0.05], np.float32))
                for k in ("cones", "mask"):
                    h.update(np.ascontiguousarray(obs[k]).tobytes())
                for k in ("boxes", "scores", "classes", "ranges", "bearings"):
                    h.update(np.ascontiguousarray(info["detections"][k]).tobytes())
                if term or trunc:
                    obs, info = env.reset()
        finally:
            env.close()
    assert h.hexdigest() == GOLDEN_672


def test_false_positives_logged_at_the_fitting_camera_land_in_the_same_place_of_another():
    model = load_model(SHIPPED_MODEL)
    from weather_gym.camera.config import CameraConfig

    point = model.point("droplets@3")
    big = FrameSampler(point, CameraConfig(width=1344, height=752), fit_camera=(672, 376))
    same = FrameSampler(point, CameraConfig(), fit_camera=(672, 376))
    ra, rb = np.random.default_rng(1), np.random.default_rng(1)
    a = np.concatenate([big(None, ra, step=t)["boxes"] for t in range(20)])  # false positives only
    b = np.concatenate([same(None, rb, step=t)["boxes"] for t in range(20)])
    assert len(a) == len(b) > 0
    np.testing.assert_allclose(a, 2 * b, rtol=1e-6)


def test_the_samplers_probabilities_are_the_models_at_knots_outside_them_and_at_nan():
    """The compiled logits reproduce np.interp's special cases: a feature exactly at a knot, below the
    first, above the last, NaN."""
    from weather_gym.surrogate.point import BEARING_KNOTS, CROWD_KNOTS, LOGH_KNOTS, RANGE_KNOTS, VIS_KNOTS
    from weather_gym.surrogate.sample import _Tables

    point = load_model(SHIPPED_MODEL).point("droplets@3")
    specials = [np.r_[k, k[0] - 1.0, k[-1] + 1.0, (k[:-1] + k[1:]) / 2, np.nan]
                for k in (RANGE_KNOTS, BEARING_KNOTS, LOGH_KNOTS, VIS_KNOTS, CROWD_KNOTS)]
    n = max(len(s) for s in specials)
    feats = tuple(np.resize(s, n) for s in specials)
    cls = np.arange(n) % 4
    got = _Tables(point).probabilities(feats, cls)
    for row, kind in enumerate(("detected", "loose", "part")):
        np.testing.assert_array_equal(got[row], point.probability_of(feats, cls, kind=kind))
    assert np.isnan(got).any() and not np.isnan(got).all()
