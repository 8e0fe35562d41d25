"""GroundTruthConeWrapper: oracle cone lists from the env's ground truth (optionally degraded)."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.perception.cones import FIELD, unpack_cones
from weather_gym.wrappers.ground_truth import OracleNoise, oracle_cones

CAM = CameraConfig()


def _gt(n=10, seed=0):
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(3, 30, n)
    bearings = rng.uniform(-0.7, 0.7, n)
    u = CAM.cx - CAM.fx * np.tan(bearings)
    h = CAM.fy * 0.325 / ranges
    boxes = np.c_[u - 0.35 * h, 200 - h, u + 0.35 * h, np.full(n, 200.0)]
    return {"boxes": boxes.astype(np.float32), "classes": rng.integers(0, 2, n), "cone_ids": np.arange(n),
            "ranges": ranges.astype(np.float32), "bearings": bearings.astype(np.float32),
            "pixels": (h * h * 0.4).astype(np.int64)}


def test_perfect_oracle_reports_every_visible_cone():
    gt = _gt()
    cones, mask = oracle_cones(gt, CAM)
    d = unpack_cones(cones, mask)
    assert mask.sum() == 10
    assert np.allclose(np.sort(d["range"]), np.sort(gt["ranges"]), atol=1e-5)
    order = np.argsort(gt["ranges"])
    assert np.array_equal(d["classes"], gt["classes"][order])
    assert np.all(d["score"] == 1.0)
    # car-frame positions follow from range and bearing with the camera's mount offset
    assert np.allclose(d["x_body"], CAM.mount_x + gt["ranges"][order] * np.cos(gt["bearings"][order]), atol=1e-4)


def test_range_and_pixel_limits():
    gt = _gt()
    cones, mask = oracle_cones(gt, CAM, OracleNoise(max_range=15.0, min_pixels=30))
    d = unpack_cones(cones, mask)
    expected = (gt["ranges"] <= 15.0) & (gt["pixels"] >= 30)
    assert mask.sum() == expected.sum() and np.all(d["range"] <= 15.0)


def test_noise_is_seeded_and_does_what_it_says():
    gt = _gt(n=40)
    noise = OracleNoise(range_noise=0.1, bearing_noise=0.02, miss_prob=0.5, false_positives=3.0, swap_prob=0.0)
    a = oracle_cones(gt, CAM, noise, np.random.default_rng(1))
    b = oracle_cones(gt, CAM, noise, np.random.default_rng(1))
    c = oracle_cones(gt, CAM, noise, np.random.default_rng(2))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])
    counts = [int(oracle_cones(gt, CAM, noise, np.random.default_rng(s))[1].sum()) for s in range(200)]
    assert np.mean(counts) == pytest.approx(40 * 0.5 + 3.0, abs=1.0)  # half missed, 3 phantoms a frame
    swapped = oracle_cones(gt, CAM, OracleNoise(swap_prob=1.0), np.random.default_rng(0))
    d = unpack_cones(*swapped)
    assert np.array_equal(d["classes"], 1 - gt["classes"][np.argsort(gt["ranges"])])


def test_bad_settings_are_rejected():
    with pytest.raises(ValueError, match="miss_prob"):
        OracleNoise(miss_prob=1.5)
    with pytest.raises(ValueError, match="max_range"):
        OracleNoise(max_range=-1.0)
    with pytest.raises(ValueError, match="Generator"):
        oracle_cones(_gt(), CAM, OracleNoise(miss_prob=0.1))


# ---- with the simulator ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def env_factory():
    gym = pytest.importorskip("gymnasium")
    import weather_gym  # noqa: F401  (registers the env ids)
    from weather_gym.wrappers import GroundTruthConeWrapper

    made = []

    def make(**kwargs):
        env = GroundTruthConeWrapper(gym.make("WeatherGym/ConeTrackSmall-v0"), **kwargs)
        made.append(env)
        return env

    yield make
    for env in made:
        env.close()


def _roll(env, seed, n=4):
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for _ in range(n):
        obs, _, _, _, info = env.step(np.array([0.0, 0.6], np.float32))
        out.append((obs, info))
    return out


@pytest.mark.slow
def test_wrapper_turns_ground_truth_into_cone_lists(env_factory):
    from weather_gym.wrappers import GroundTruthConeWrapper

    env = env_factory()
    assert isinstance(env, GroundTruthConeWrapper)
    steps = _roll(env, seed=0)
    track = env.unwrapped.track
    for obs, info in steps:
        assert env.observation_space.contains(obs)
        assert sorted(obs) == ["cones", "mask", "state"]
        gt = info["gt"]
        assert obs["mask"].sum() == min(len(gt["classes"]), 64) > 5
        # each reported cone, put back into the track frame with the true pose, is a real cone
        d = unpack_cones(obs["cones"], obs["mask"])
        x, y, yaw = info["pose"]
        c, s = np.cos(yaw), np.sin(yaw)
        world = np.c_[x + c * d["x_body"] - s * d["y_body"], y + s * d["x_body"] + c * d["y_body"]]
        err = np.hypot(*(world[:, None, :] - track.cones_xy[None, :, :]).transpose(2, 0, 1)).min(axis=1)
        assert np.median(err) < 0.15 and err.max() < 0.5
    assert obs["cones"][:, FIELD["score"]].max() == 1.0


@pytest.mark.slow
def test_wrapper_noise_is_reproducible_and_leaves_the_env_alone(env_factory):
    noisy = env_factory(miss_prob=0.3, range_noise=0.05, false_positives=1.0)
    a = _roll(noisy, seed=3)
    b = _roll(noisy, seed=3)
    for (oa, _), (ob, _) in zip(a, b):
        assert all(np.array_equal(oa[k], ob[k]) for k in oa)
    c = _roll(noisy, seed=4)
    assert any(not np.array_equal(oa["cones"], oc["cones"]) for (oa, _), (oc, _) in zip(a, c))
    # the env's own random stream (odometry noise) is the same with and without the oracle's noise
    clean = _roll(env_factory(), seed=3)
    for (oa, _), (oc, _) in zip(a, clean):
        assert np.array_equal(oa["state"], oc["state"])


@pytest.mark.slow
def test_keep_image_and_bad_options(env_factory):
    env = env_factory(keep_image=True)
    obs, _ = env.reset(seed=0)
    assert obs["image"].shape == env.observation_space["image"].shape
    with pytest.raises(ValueError, match="unknown option"):
        env_factory(miss=0.2)
