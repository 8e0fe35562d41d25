"""perception="surrogate": the detector path's observation and info, nothing rendered, same seed same bytes."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.pipeline import make_env
from weather_gym.weather.presets import preset_spec

ACTION = np.array([0.4, 0.05], np.float32)


def _run(env, seed, steps=25, options=None):
    obs, info = env.reset(seed=seed, options=options)
    out = [obs["cones"].tobytes() + obs["mask"].tobytes()]
    for _ in range(steps):
        obs, _, _, _, info = env.step(ACTION)
        out.append(obs["cones"].tobytes() + obs["mask"].tobytes())
    return out, info


@pytest.fixture
def no_render(monkeypatch):
    from weather_gym.sim.world import World

    def boom(*a, **k):
        raise AssertionError("the camera was rendered")

    monkeypatch.setattr(World, "render", boom)


def test_same_space_and_info_keys_as_the_detector_path():
    sur = make_env(perception="surrogate", weather="droplets@2", max_episode_steps=5)
    det = make_env(perception="detector", weather="droplets@2", max_episode_steps=5)
    try:
        assert sur.observation_space == det.observation_space
        assert sur.action_space == det.action_space
        o1, i1 = sur.reset(seed=0)
        o2, i2 = det.reset(seed=0)
        assert sorted(i1) == sorted(i2)
        assert sorted(i1["detections"]) == sorted(i2["detections"])
        for k in i1["detections"]:
            assert i1["detections"][k].dtype == i2["detections"][k].dtype, k
        assert sur.observation_space.contains(o1)
    finally:
        sur.close()
        det.close()


def test_nothing_rendered_and_same_seed_same_bytes(no_render):
    env = make_env(perception="surrogate", weather="low_light@2", max_episode_steps=100)
    try:
        assert env.unwrapped.renderer == "none"
        a, _ = _run(env, seed=3)
        b, _ = _run(env, seed=3)
        c, _ = _run(env, seed=4)
        assert a == b
        assert a != c
        assert sum(np.frombuffer(x[-64:], np.int8).sum() for x in a) > 0  # it reports cones
    finally:
        env.close()


def test_weather_changes_pick_the_condition(no_render):
    env = make_env(perception="surrogate", max_episode_steps=100)
    try:
        _, info = env.reset(seed=0)
        assert "weather" not in info  # no weather given: as the detector path without a WeatherWrapper
        _, info = env.reset(seed=0, options={"weather": "low_light@3"})
        assert info["weather"][0]["name"] == "dim"
        wrapper = env.get_wrapper_attr("set_weather")
        assert wrapper("droplets@1")[0]["name"] == "droplets"
        _, _, _, _, info = env.step(ACTION)
        assert info["weather"][0]["k"] == pytest.approx(preset_spec("droplets", 1)[0]["k"])
        with pytest.raises(InputError, match="one weather effect at a time"):
            wrapper("droplets@3,low_light@1")
        # darker: fewer cones reported than in clear weather, on the same frames
        clear, _ = _run(env, seed=1, steps=60, options={"weather": "clear"})
        dark, _ = _run(env, seed=1, steps=60, options={"weather": "low_light@4"})
        count = lambda frames: sum(int(np.frombuffer(x[-64:], np.int8).sum()) for x in frames)  # noqa: E731
        assert count(dark) < 0.5 * count(clear)
    finally:
        env.close()


def test_bad_settings_are_typed_errors(tmp_path):
    with pytest.raises(InputError, match="k=0.99 is beyond"):
        make_env(perception="surrogate", weather={"dim": {"k": 0.99, "mode": "night"}})  # it ends at low_light@4
    with pytest.raises(InputError, match="fitted with other effect parameters"):
        make_env(perception="surrogate", weather={"droplets": {"k": 0.3, "mode": "faithful"}})
    with pytest.raises(InputError, match="does not exist"):
        make_env(perception="surrogate", perception_kwargs={"model": str(tmp_path / "none.npz")})


def test_vector_envs_set_the_weather_per_env(no_render):
    from weather_gym.pipeline import make_vec_env

    envs = make_vec_env(num_envs=2, perception="surrogate", vectorization_mode="sync", max_episode_steps=20)
    try:
        envs.reset(seed=0)
        envs.set_attr("weather", ["clear", "low_light@4"])
        total = np.zeros(2)
        for _ in range(15):
            obs, *_ = envs.step(np.tile(ACTION, (2, 1)))
            total += obs["mask"].sum(axis=1)
        assert total[1] < 0.5 * total[0]  # almost nothing is seen at low_light@4
    finally:
        envs.close()


def test_weather_randomizer_drives_the_surrogate(no_render):
    from weather_gym.wrappers import RandomWeather, WeatherRandomizer

    env = WeatherRandomizer(make_env(perception="surrogate", max_episode_steps=30),
                            RandomWeather(presets=("droplets", "low_light"), severities=(1, 2, 3, 4)))
    try:
        names = set()
        for seed in range(4):
            _, info = env.reset(seed=seed)
            names.add(info["weather"][0]["name"])
            assert info["weather_draw"].split("@")[0] in ("droplets", "low_light")
        assert names == {"droplets", "dim"}
    finally:
        env.close()


NOISY_CAMERA = {"enabled": True, "read_noise": 2.0}
IDEAL_CAMERA = {"enabled": False}


@pytest.mark.parametrize(("weather", "camera", "option", "still"), [
    (None, IDEAL_CAMERA, None, True),
    ("droplets@2", IDEAL_CAMERA, None, False), ("droplets@2", None, None, False),
    ("low_light@1", IDEAL_CAMERA, None, False), ("low_light@2", None, None, False),  # the night camera's gain noise
    (None, None, None, True),  # the default camera's noise: still held
    (None, IDEAL_CAMERA, NOISY_CAMERA, True),  # a noisy camera model given per episode
])
def test_a_standing_car_sees_a_still_frame_only_in_still_weather(weather, camera, option, still):
    """The detector is a function of the image: a car that stands in clear weather gets the same cones
    every frame (so a car that stopped seeing stays stopped); per-frame droplets and the night camera's
    gain noise change the image, and the cones, every frame. A camera's own sensor noise jitters pixels,
    not which cones are found."""
    env_kwargs = {} if camera is None else {"camera_model": camera}
    env = make_env(perception="surrogate", weather=weather, max_episode_steps=40, **env_kwargs)
    try:
        env.reset(seed=3, options=None if option is None else {"camera_model": option})
        for _ in range(15):  # drive off, so the cones' states are mid-episode ones
            env.step(np.array([0.0, 0.6], np.float32))
        lists = []
        for _ in range(40 - 16):
            obs, _, term, trunc, info = env.step(np.array([0.0, -1.0], np.float32))  # brake: it stands
            if info["speed"] == 0.0:
                lists.append(obs["cones"].tobytes() + obs["mask"].tobytes())
            assert not term and not trunc
        assert len(lists) >= 5
        assert (len(set(lists)) == 1) == still
        held = copy.deepcopy(info["detections"])  # a held frame's detections copy and pickle as any
        assert np.array_equal(held["boxes"], info["detections"]["boxes"])
    finally:
        env.close()


def test_a_car_standing_for_a_long_time_keeps_plain_detections():
    """Regression: each held frame wrapped the last detections once more, and after ~1,000 frames of
    standing, copying the info (as vector envs and SB3 do) hit the recursion limit."""
    env = make_env(perception="surrogate", weather="low_light@1", max_episode_steps=1300, camera_model=IDEAL_CAMERA)
    try:
        env.reset(seed=3)
        for _ in range(1200):
            _, _, term, trunc, info = env.step(np.array([0.0, -1.0], np.float32))
        assert not term and not trunc and info["speed"] == 0.0
        copy.deepcopy(info)
    finally:
        env.close()


def _first_frame(env, seed=0):
    """Cone id -> (box height in camera pixels, the model's box-height feature) on the first frame."""
    _, info = env.reset(seed=seed)
    gt = info["gt"]
    box_h = np.asarray(gt["boxes"])[:, 3] - np.asarray(gt["boxes"])[:, 1]
    factor = env.get_wrapper_attr("box_factor")
    return {int(i): (h, h * factor) for i, h in zip(gt["cone_ids"], box_h, strict=True)}


@pytest.mark.parametrize("size", [(336, 188), (1280, 720)])
def test_any_camera_size_scales_the_box_feature_to_the_detectors_input(no_render, size):
    """A model fitted at 672x376 runs at other cameras: the same cone gets the box height it has at the
    detector's input there (the input follows the camera: at 336x188 half the 672x376 one)."""
    from weather_gym.perception.labels import input_scale
    from weather_gym.surrogate.camera import detector_input_size

    ref = make_env(perception="surrogate", weather="droplets@3", max_episode_steps=30)
    env = make_env(perception="surrogate", weather="droplets@3", max_episode_steps=30,
                   camera={"width": size[0], "height": size[1]})
    try:
        assert ref.get_wrapper_attr("box_factor") == 1.0
        scale = input_scale(size, detector_input_size(*size))
        assert env.get_wrapper_attr("box_factor") == pytest.approx(scale / input_scale((672, 376), (512, 288)))
        assert env.get_wrapper_attr("range_factor") == pytest.approx(672 / size[0])  # same field of view
        a, b = _first_frame(ref), _first_frame(env)
        common = [i for i in a if i in b and a[i][0] > 20 and b[i][0] > 10]  # whole near cones in both
        assert len(common) >= 2
        # the feature is the box height at the detector's input: camera pixels x the input scale
        ratio = np.array([b[i][1] / a[i][1] for i in common])
        np.testing.assert_allclose(ratio, size[1] / 376 * scale / (512 / 672), rtol=0.05)
        out, info = _run(env, seed=0, steps=20)
        assert sum(np.frombuffer(x[-64:], np.int8).sum() for x in out) > 0  # it reports cones
    finally:
        ref.close()
        env.close()


def test_the_fitting_camera_keeps_its_samples(no_render):
    """At 672x376 the box feature is the camera's own box height (factor exactly 1, nothing rescaled)."""
    env = make_env(perception="surrogate", weather="droplets@3", max_episode_steps=30)
    try:
        assert env.get_wrapper_attr("box_factor") == 1.0
        assert env.get_wrapper_attr("_sampler")._rescale_fp is False
    finally:
        env.close()


@pytest.mark.parametrize("weather", ["rain@2", "fog@1", {"blur": 0.5}])
def test_a_nominal_effect_falls_back_to_clear_with_a_warning(no_render, weather):
    from weather_gym.surrogate.conditions import SurrogateFallbackWarning

    with pytest.warns(SurrogateFallbackWarning, match="modelled as clear weather"):
        env = make_env(perception="surrogate", weather=weather, max_episode_steps=30)
    clear = make_env(perception="surrogate", weather="clear", max_episode_steps=30)
    try:
        got, info = _run(env, seed=2, steps=10)
        assert "no fit of weather effect" in info["surrogate_fallback"]
        assert env.get_wrapper_attr("fallback") == info["surrogate_fallback"]
        assert info["weather"][0]["name"] != "droplets"  # the weather reported is the one asked for
        want, clear_info = _run(clear, seed=2, steps=10)
        assert got == want and "surrogate_fallback" not in clear_info  # clear weather's draws
        with pytest.warns(SurrogateFallbackWarning):
            env.get_wrapper_attr("set_weather")("droplets@3,rain@1")  # the fitted effect stays
        _, info = env.reset(seed=2)
        assert "rain" in info["surrogate_fallback"] and env.get_wrapper_attr("fallback")
        env.get_wrapper_attr("set_weather")("droplets@3")
        _, info = env.reset(seed=2)
        assert "surrogate_fallback" not in info and env.get_wrapper_attr("fallback") is None
    finally:
        env.close()
        clear.close()


def test_the_fallback_warning_names_the_effect_once_whatever_its_severity(no_render):
    """The warning's text leaves out k, so Python's default filter shows it once per effect and place
    (a severity sweep over rain does not repeat it); ``fallback`` and the info keep the k."""
    import warnings

    from weather_gym.surrogate.conditions import SurrogateFallbackWarning

    env = make_env(perception="surrogate", weather="clear", max_episode_steps=30)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            for spec in ("rain@1", "rain@2", "rain:0.3", "fog@1"):
                env.get_wrapper_attr("set_weather")(spec)
        texts = [str(w.message) for w in caught if issubclass(w.category, SurrogateFallbackWarning)]
        assert len(texts) == 2 and "effect rain:" in texts[0] and "effect fog:" in texts[1]
        assert "(k " not in texts[0] and "fog (k 0." in env.get_wrapper_attr("fallback")
    finally:
        env.close()


def test_an_unknown_effect_still_raises():
    with pytest.raises(InputError, match="hail"):
        make_env(perception="surrogate", weather="hail@2")
