"""The PyBullet world and the camera sensor: images, metric depth, ground-truth boxes, cone hits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.sim.config import SimConfig
from weather_gym.sim.ego import ego_overlay
from weather_gym.sim.look import sample_look
from weather_gym.sim.world import World
from weather_gym.tracks import load_track


@pytest.fixture(scope="module", params=["realistic", "plain"])
def world(request):
    """The default (realistic) world and the plain one."""
    w = World(load_track("acceleration"), camera=CameraConfig(width=224, height=126), sim=SimConfig(scene=request.param))
    yield w
    w.close()


def test_frame_shapes_and_types(world):
    world.reset(world.track.start_pose)
    f = world.render()
    assert f.rgb.shape == (126, 224, 3) and f.rgb.dtype == np.uint8
    assert f.depth.shape == (126, 224) and f.depth.dtype == np.float32
    assert np.isfinite(f.depth).all() and f.depth.max() <= world.camera_config.far
    assert f.segmentation.dtype == np.int32


def test_sky_is_not_white(world):
    world.reset(world.track.start_pose)
    top = world.render().rgb[:10].reshape(-1, 3).astype(float)
    # blue sky, so white droplets stay visible (the realistic sky is paler, as a real camera sees it)
    assert top.mean(axis=0)[2] > top.mean(axis=0)[0] + (10 if world.realistic else 20)


def test_ground_truth_boxes_cover_their_cone_pixels_and_depth_is_metric(world):
    world.reset(world.track.start_pose)
    f = world.render()
    gt = f.gt
    assert len(gt["boxes"]) > 4
    cam = world.camera_config
    ego = ego_overlay(world.look.ego_seed, cam.width, cam.height) if world.realistic and world.look.ego_seed >= 0 else None
    for box, cid, rng_m, bearing, pixels in zip(gt["boxes"], gt["cone_ids"], gt["ranges"], gt["bearings"], gt["pixels"]):
        x1, y1, x2, y2 = box.astype(int)
        mask = f.segmentation == cid
        assert mask.sum() == pixels
        ys, xs = np.nonzero(mask)
        assert (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1) == (x1, y1, x2, y2)
        if ego is not None and ego.mask[y1:y2 + 1, max(0, x1 - 1):x2 + 1].any():
            assert not (ego.mask & mask).any()  # the ego car's wheel or nose hides part of it: the box is the rest
            continue
        # bearing of the box centre agrees with the true bearing (pinhole model)
        assert cam.bearing((x1 + x2) / 2) == pytest.approx(float(bearing), abs=0.03)
        # the nearest depth inside the cone's mask is the z-distance to its near surface
        z_true = rng_m * math.cos(bearing)
        assert float(f.depth[mask].min()) == pytest.approx(z_true, rel=0.1, abs=0.3)


def test_occluded_cones_have_fewer_pixels_than_their_box(world):
    # Looking down the lane, far cones hide behind near ones only partly: boxes stay the visible part
    world.reset(world.track.start_pose)
    gt = world.render().gt
    areas = (gt["boxes"][:, 2] - gt["boxes"][:, 0]) * (gt["boxes"][:, 3] - gt["boxes"][:, 1])
    assert (gt["pixels"] <= areas).all()


def test_look_changes_the_image_and_is_restored(world):
    world.reset(world.track.start_pose)
    own = world.look
    a = world.render().rgb
    world.set_look(sample_look(np.random.default_rng(4)))
    b = world.render().rgb
    world.set_look(own)
    c = world.render().rgb
    assert np.abs(a.astype(int) - b).mean() > 5
    assert np.array_equal(a, c)


def test_driving_into_a_cone_knocks_it_and_reset_restores_it(world):
    track = world.track
    idx = 5
    cx, cy = track.cones_xy[idx]
    world.reset((cx - 6.0, cy, 0.0), speed=6.0)
    touched = set()
    for _ in range(60):
        touched |= world.step(0.0, 0.3)
    assert idx in touched
    assert world.cone_displacement()[idx] > 0.2
    world.reset(track.start_pose)
    assert world.cone_displacement().max() == 0.0


def test_tiny_and_auto_renderers_are_each_deterministic():
    track = load_track("hairpin")
    for renderer in ("tiny", "auto"):
        frames = []
        for _ in range(2):
            w = World(track, sim=SimConfig(renderer=renderer), camera=CameraConfig(width=128, height=72))
            w.reset(track.start_pose)
            for _ in range(5):
                w.step(0.1, 0.5)
            frames.append(w.render())
            w.close()
        assert np.array_equal(frames[0].rgb, frames[1].rgb), renderer
        assert np.array_equal(frames[0].depth, frames[1].depth), renderer


def test_gui_without_display_is_a_clear_error(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.raises(RuntimeError, match="display"):
        World(load_track("hairpin"), sim=SimConfig(gui=True))


def _renderer_in_forked_child(queue):
    import faulthandler
    import warnings

    faulthandler.dump_traceback_later(50)  # should it hang: where, in the test's captured output
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        w = World(load_track("acceleration"), camera=CameraConfig(width=32, height=18))
        try:
            w.reset(w.track.start_pose)
            queue.put((w.renderer_name, w.render().rgb.tobytes(), [str(c.message) for c in caught]))
        finally:
            w.close()


def test_a_child_forked_after_egl_renders_with_egl_the_same_bytes(world):
    import multiprocessing as mp

    from weather_gym.sim import renderer

    if world.renderer_name != "egl":
        pytest.skip("EGL is not available here")
    if "llvmpipe" not in renderer.renderer_detail():
        pytest.skip("a hardware EGL cannot be used after fork")
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    proc = ctx.Process(target=_renderer_in_forked_child, args=(q,))
    proc.start()
    try:
        name, frame, warned = q.get(timeout=60)  # EGL in a forked child used to wait here forever
    finally:
        proc.join(timeout=10)
        if proc.is_alive():
            proc.kill()
    here = World(load_track("acceleration"), camera=CameraConfig(width=32, height=18))
    try:
        here.reset(here.track.start_pose)
        assert (name, frame) == ("egl", here.render().rgb.tobytes())  # no silent change of renderer
    finally:
        here.close()
    assert warned == []


@pytest.mark.parametrize("requested", ["egl", "auto"])
def test_egl_in_a_forked_child_that_cannot_use_it_is_a_clear_error(world, monkeypatch, requested):
    from weather_gym.sim import renderer

    monkeypatch.setattr(renderer, "_forked_after_egl", True)
    monkeypatch.delenv("WEATHER_GYM_RENDERER", raising=False)
    with pytest.raises(RuntimeError, match="forked from one that already used.*spawn"):  # never a silent switch
        World(load_track("acceleration"), sim=SimConfig(renderer=requested), camera=CameraConfig(width=32, height=18))


@pytest.mark.parametrize("scene", ["realistic", "plain"])
def test_a_world_without_camera_frames_shows_its_look_in_the_chase_view(scene):
    """Renderer 'none' (cone-list scenarios) makes its textures only when the chase view needs them:
    the chase view is the same as a rendering world's, and follows every look set before it."""
    track = load_track("small_track")
    other = sample_look(np.random.default_rng(4))
    views = {}
    for renderer in ("tiny", "none"):
        w = World(track, sim=SimConfig(renderer=renderer, scene=scene))
        try:
            w.reset(track.start_pose)
            own = w.look
            a = w.render_chase(160, 90)
            w.set_look(other)
            w.set_look(own)  # set and set back before any view: nothing of `other` may show
            b = w.render_chase(160, 90)
            w.set_look(other)
            views[renderer] = (a, b, w.render_chase(160, 90))
        finally:
            w.close()
    for tiny, none in zip(views["tiny"], views["none"], strict=True):
        assert np.array_equal(tiny, none)
    a, b, c = views["none"]
    assert np.array_equal(a, b)
    assert np.abs(a.astype(int) - c).mean() > 5
