"""The realistic world: FS cone stripes, clutter outside the corridor and never labelled, the ego car's
overlay never labelled, domain randomisation ranges, same seed same bytes."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import SMALL_CAMERA
from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.errors import FileFormatError, InputError
from weather_gym.sim.ego import clip_ground_truth, ego_overlay
from weather_gym.sim.randomize import RandomizeRanges, sample_realistic
from weather_gym.sim.scenery import CLEARANCE_M, clutter_layout, corridor_clearance
from weather_gym.sim.scenery_textures import BODY_RGB, STRIPE_RGB, realistic_cone_texture, stripe_rows
from weather_gym.tracks import load_track


@pytest.mark.parametrize("cls, n_stripes", [("blue", 1), ("yellow", 1), ("orange", 2), ("big_orange", 2)])
def test_cone_texture_has_the_class_stripes(cls, n_stripes):
    tex = realistic_cone_texture(cls).astype(float)
    rows = stripe_rows(cls)
    assert len(rows) == n_stripes
    for r0, r1 in rows:
        mid = tex[(r0 + r1) // 2].mean(axis=0)
        assert np.abs(mid - STRIPE_RGB[cls]).max() < 25
    body = tex[int(0.3 * len(tex))].mean(axis=0)  # upper body, between the top and the stripes
    assert np.abs(body - BODY_RGB[cls]).max() < 25
    # yellow's stripe is black, the others' white
    assert (tex[(rows[0][0] + rows[0][1]) // 2].mean() < 60) == (cls == "yellow")


@pytest.mark.parametrize("track", ["small_track", "random:4"])
def test_clutter_stays_outside_the_corridor(track):
    t = load_track(track)
    for seed in (0, 17, 63):
        items = clutter_layout(t, seed)
        assert len(items) > 20
        corners = np.concatenate([it.footprint for it in items])
        assert corridor_clearance(t, corners).min() >= CLEARANCE_M
    # the check itself: a point on the centerline is inside
    assert corridor_clearance(t, np.asarray(t.centerline[:1])).min() < 0


def test_clutter_layout_out_of_range():
    with pytest.raises(ValueError, match="clutter layout"):
        clutter_layout(load_track("small_track"), 64)


def test_ego_overlay_cuts_boxes():
    ov = ego_overlay(2, 160, 90)
    top = int(ov.top[80])
    gt = ConeArrays(boxes=np.array([[78, 10, 82, 20], [78, top - 5, 82, top + 5], [78, top + 2, 82, 89]], np.float32),
                    classes=np.array([0, 1, 0]), pixels=np.array([40, 40, 40]))
    cut = clip_ground_truth(gt, ov)
    assert cut.count == 2  # the box wholly behind the car is dropped
    assert cut["boxes"][1, 3] <= top + 0.5 and cut["pixels"][1] < 40
    assert np.array_equal(cut["boxes"][0], gt["boxes"][0])


def test_randomize_ranges_are_validated():
    with pytest.raises(InputError, match="exposure_ev"):
        RandomizeRanges(exposure_ev=(2.0, 1.0))
    with pytest.raises(InputError, match="k1"):
        RandomizeRanges().override({"k1": "-0.9,0"})
    with pytest.raises(InputError, match="nosuch"):
        RandomizeRanges().override({"nosuch": "0,1"})
    with pytest.raises(InputError, match="p_ego"):
        RandomizeRanges(p_ego=1.5)
    r = RandomizeRanges().override({"exposure_ev": "2.5,2.5", "p_ego": "0"})
    draws = [sample_realistic(np.random.default_rng(i), r) for i in range(5)]
    assert all(d.camera_model.exposure_ev == 2.5 and d.look.ego_seed == -1 for d in draws)
    assert sample_realistic(np.random.default_rng(1), r) == draws[1]


def test_randomize_ranges_from_toml(tmp_path):
    good = tmp_path / "r.toml"
    good.write_text("exposure_ev = [-0.5, 0.5]\np_jpeg = 0.0\n")
    assert RandomizeRanges.from_toml(good).exposure_ev == (-0.5, 0.5)
    bad = tmp_path / "bad.toml"
    bad.write_text("vignetting = [0.5, 0.1]\n")
    with pytest.raises(FileFormatError, match="vignetting"):
        RandomizeRanges.from_toml(bad)


@pytest.fixture(scope="module")
def realistic_env():
    from weather_gym.camera.isp import CameraModel
    from weather_gym.envs import ConeTrackEnv, EnvConfig
    from weather_gym.sim.config import SimConfig

    # the world alone: the camera model (lens distortion, noise, JPEG) is tested in tests/camera/test_isp.py
    env = ConeTrackEnv(EnvConfig(track="small_track", camera=SMALL_CAMERA.scaled(192, 108),
                                 sim=SimConfig(scene="realistic"), camera_model=CameraModel.ideal()))
    yield env
    env.close()


def _look(**kw):
    from dataclasses import replace

    from weather_gym.sim.look import DEFAULT_LOOK

    return replace(DEFAULT_LOOK, **kw)


def test_realistic_render_same_seed_same_bytes(realistic_env):
    draw = sample_realistic(np.random.default_rng(3))
    opts = {"look": draw.look, "camera_model": draw.camera_model, "start_s": 12.0}
    a, _ = realistic_env.reset(seed=7, options=opts)
    realistic_env.reset(seed=8, options={"look": _look(clutter_seed=5)})  # something else in between
    b, _ = realistic_env.reset(seed=7, options=opts)
    assert np.array_equal(a["image"], b["image"]) and np.array_equal(a["depth"], b["depth"])


def test_clutter_and_ego_are_never_labelled(realistic_env):
    from weather_gym.sim.ego import EGO_DEPTH_M

    world = realistic_env.world
    for seed in (0, 9):
        obs, info = realistic_env.reset(seed=0, options={"look": _look(clutter_seed=seed, ego_seed=4), "start_s": 3.0})
        assert world._cone_lut[world._clutter_body + 1] == -1
        frame = world.render()
        ov = ego_overlay(4, *frame.rgb.shape[1::-1])
        assert (frame.segmentation[ov.mask] == -1).all()
        assert np.allclose(obs["depth"][ov.mask], EGO_DEPTH_M)
        gt = info["gt"]
        assert gt.count > 0 and set(gt["cone_ids"].tolist()) <= set(range(len(world.cone_classes)))
        # what the segmentation labels is a subset of what geometry says is there (clutter only hides)
        geo = world.ground_truth()
        assert set(gt["cone_ids"].tolist()) <= set(geo["cone_ids"].tolist())


def test_realistic_cones_show_their_stripe(realistic_env):
    obs, info = realistic_env.reset(seed=0, options={"look": _look(), "start_s": 3.0})
    gt = info["gt"]
    big = int(np.argmax(gt["pixels"]))
    x0, y0, x1, y1 = gt["boxes"][big].astype(int)
    patch = obs["image"][y0:y1, x0:x1].reshape(-1, 3).astype(int)
    cls = int(gt["classes"][big])
    if cls == 1:  # yellow: a dark stripe
        assert (patch.max(axis=1) < 70).any()
    else:  # a white stripe
        assert (patch.min(axis=1) > 170).any()


def test_scenario_camera_model_table(tmp_path):
    from weather_gym.envs.scenario import build_config, load_scenario, scenario_files

    real = next(p for p in scenario_files() if p.name == "cone_track_realistic.toml")
    cfg = build_config(load_scenario(real))
    assert cfg.sim.scene == "realistic" and cfg.camera_model.enabled and cfg.camera_model.white_balance[2] == 1.04
    bad = tmp_path / "bad.toml"
    bad.write_text('id = "WeatherGym/X-v0"\n[camera_model]\nenabled = true\nexposure_ev = 40\n')
    with pytest.raises(FileFormatError, match="exposure_ev"):
        load_scenario(bad)
    bad.write_text('id = "WeatherGym/X-v0"\n[camera_model]\nexposure = 1\n')
    with pytest.raises(InputError, match="exposure"):
        load_scenario(bad)


def test_realistic_scene_defaults_to_the_realistic_look(realistic_env):
    from weather_gym.sim.look import REALISTIC_LOOK

    realistic_env.reset(seed=1)
    assert realistic_env.world.look == REALISTIC_LOOK and REALISTIC_LOOK.ego_seed >= 0
    realistic_env.reset(seed=1, options={"look": "random"})
    random_look = realistic_env.world.look
    assert random_look != REALISTIC_LOOK and 0 <= random_look.clutter_seed < 64


def test_knocked_cone_leaves_no_contact_shadow_and_reset_restores_it():
    import pybullet as p

    from weather_gym.camera.config import CameraConfig
    from weather_gym.sim.config import SimConfig
    from weather_gym.sim.world import World

    track = load_track("acceleration")
    w = World(track, sim=SimConfig(scene="realistic"), camera=CameraConfig(width=96, height=54))
    try:
        idx = 5
        cx, cy = track.cones_xy[idx]
        z = lambda: p.getBasePositionAndOrientation(w._shadow_bodies[idx], physicsClientId=w.client)[0][2]  # noqa: E731
        w.reset((cx - 6.0, cy, 0.0), speed=6.0)
        assert z() == 0.0
        touched = set()
        for _ in range(60):
            touched |= w.step(0.0, 0.3)
        assert idx in touched and z() < -10
        w.reset(track.start_pose)
        assert z() == 0.0 and w.cone_displacement().max() == 0.0
    finally:
        w.close()
