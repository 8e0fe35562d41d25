"""EGL frames that keep the shadow map of the frame before and redraw only where something moved
(``weather_gym.sim.egl_shadow_reuse``): the frames (the camera's and the chase view's) must keep the
bytes of frames whose whole map is redrawn, through knocked cones, new looks, chase views in between
and several worlds at once; a map drawn outside the plan (a frame of your own) makes the next one whole."""

from __future__ import annotations

import threading
import time
import types

import numpy as np
import pybullet as p
import pytest

from weather_gym.errors import InputError
from weather_gym.sim import egl_shadow_reuse
from weather_gym.sim.config import SimConfig
from weather_gym.sim.egl_shadow_reuse import ShadowMapReuse, light_basis, texel_rect
from weather_gym.sim.look import sample_look
from weather_gym.sim.randomize import sample_realistic
from weather_gym.sim.world import World
from weather_gym.tracks import load_track

SIZE = (4096, 4096)


@pytest.mark.parametrize("light", [(0.32, 0.23, 0.92), (-0.5, 0.55, 0.67), (0.9, 0.1, 0.3), (0.0, 0.0, 1.0)])
def test_the_map_axes_are_orthonormal_and_across_the_light(light):
    x, y = light_basis(light)
    n = np.asarray(light) / np.linalg.norm(light)
    assert np.allclose([x @ x, y @ y, x @ y, x @ n, y @ n], [1, 1, 0, 0, 0])


def test_texel_rect_covers_each_sphere_and_nothing_off_the_map():
    light = (0.0, 0.0, 1.0)  # straight down: the map's axes are -x and -y (bullet3's light frame)
    assert [list(v) for v in light_basis(light)] == [[-1, 0, 0], [0, -1, 0]]
    assert texel_rect([], light, SIZE) == (0, 0, 0, 0)
    # 1 m around the origin: 204.8 texels a metre, plus 2 texels of margin, around the centre
    assert texel_rect([(0.0, 0.0, 0.0, 1.0)], light, SIZE) == (1841, 1841, 414, 414)
    assert texel_rect([(30.0, 0.0, 0.0, 1.0)], light, SIZE) == (0, 0, 0, 0)  # 30 m out: off the map
    assert texel_rect([(-9.9, 9.9, 0.0, 1.0)], light, SIZE) == (3868, 0, 228, 228)  # at a corner: clipped
    two = texel_rect([(0.0, 0.0, 0.0, 0.5), (-5.0, 5.0, 0.0, 0.5)], light, SIZE)
    for one in (texel_rect([(0.0, 0.0, 0.0, 0.5)], light, SIZE), texel_rect([(-5.0, 5.0, 0.0, 0.5)], light, SIZE)):
        assert two[0] <= one[0] and two[1] <= one[1]
        assert two[0] + two[2] >= one[0] + one[2] and two[1] + two[3] >= one[1] + one[3]


@pytest.mark.parametrize("radius", [-1.0, float("nan"), float("inf")])
def test_declared_sizes_are_checked(radius):
    with pytest.raises(InputError, match="radius must be a finite distance >= 0"):
        ShadowMapReuse(0).declare(3, radius)


def test_the_environment_variable_switches_it_off(monkeypatch):
    monkeypatch.setattr(egl_shadow_reuse, "_hook", None)
    monkeypatch.setattr(egl_shadow_reuse, "_reason", None)
    monkeypatch.setenv("WEATHER_GYM_SHADOW_MAP_REUSE", "0")
    assert egl_shadow_reuse.unavailable_reason() == "WEATHER_GYM_SHADOW_MAP_REUSE=0"


def _worlds(track, scene):
    reused, whole = World(track, sim=SimConfig(scene=scene)), World(track, sim=SimConfig(scene=scene))
    if reused.renderer_name != "egl":
        reused.close(), whole.close()
        pytest.skip("EGL does not load here")
    reason = egl_shadow_reuse.unavailable_reason() if reused.camera.shadow_reuse is not None else "switched off"
    if reason is not None:
        reused.close(), whole.close()
        pytest.skip(f"no shadow-map reuse here: {reason}")
    whole.camera.shadow_reuse = None  # the plugin's own way: the whole map every frame
    return reused, whole


@pytest.mark.slow
@pytest.mark.parametrize("track_name, scene", [("hairpin", "plain"), ("small_track", "realistic")])
def test_frames_keep_their_bytes_through_knocked_cones_new_looks_and_chase_views(track_name, scene):
    track = load_track(track_name)
    reused, whole = _worlds(track, scene)
    rng = np.random.default_rng(1)
    try:
        frames = knocked = 0
        for episode in range(2):
            look = sample_realistic(rng).look if scene == "realistic" else sample_look(rng)
            for w in (reused, whole):
                w.set_look(look)
                w.reset(track.start_pose)
            for i in range(110):
                for w in (reused, whole):  # weaving across the cone lines: cones fall and roll
                    w.step(0.9 * np.sin(i / 6.0), 0.7)
                if i % 40 == 39:  # a chase-view frame in between (the car's visual body moves in and out)
                    assert np.array_equal(reused.render_chase(), whole.render_chase()), f"chase, step {i}"
                a, b = reused.render(), whole.render()
                assert np.array_equal(a.rgb, b.rgb), f"episode {episode}, step {i}"
                frames += 1
            knocked += len(reused._dynamic_cones)
        assert knocked >= 2  # the test saw cones move
        assert reused.camera.shadow_reuse.redrawn_whole < frames / 4  # and most frames kept most of the map
    finally:
        reused.close(), whole.close()


@pytest.mark.slow
def test_worlds_rendered_in_turns_keep_their_own_maps():
    tracks = [load_track("small_track"), load_track("hairpin")]
    pairs = [_worlds(t, "plain") for t in tracks]
    try:
        for w_pair, t in zip(pairs, tracks, strict=True):
            for w in w_pair:
                w.reset(t.start_pose)
        for i in range(60):
            for reused, whole in pairs:
                for w in (reused, whole):
                    w.step(0.3 * np.sin(i / 8.0), 0.6)
            got = [reused.render().rgb for reused, _ in pairs]  # the reusing worlds one after another
            for (_, whole), rgb in zip(pairs, got, strict=True):
                assert np.array_equal(rgb, whole.render().rgb), f"step {i}"
    finally:
        for w_pair in pairs:
            for w in w_pair:
                w.close()


def test_a_frame_of_your_own_on_the_worlds_client_makes_the_next_map_whole():
    track = load_track("hairpin")
    reused, whole = _worlds(track, "plain")
    try:
        for w in (reused, whole):
            w.reset(track.start_pose)
        for _ in range(4):
            for w in (reused, whole):
                w.step(0.0, 0.5)
            assert np.array_equal(reused.render().rgb, whole.render().rgb)
        redrawn = reused.camera.shadow_reuse.redrawn_whole
        # your own frame, lit from elsewhere: the plugin draws the whole map for that light
        reused._activate()  # its EGL context current, as in a process with one world
        light = {**reused._light, "lightDirection": [-0.5, 0.55, 0.67]}
        view = p.computeViewMatrix([0, 0, 5], [5, 0, 0], [0, 0, 1])
        p.getCameraImage(64, 64, view, p.computeProjectionMatrixFOV(60, 1, 0.1, 50),
                         renderer=p.ER_BULLET_HARDWARE_OPENGL, physicsClientId=reused._client, **light)
        for _ in range(3):
            assert np.array_equal(reused.render().rgb, whole.render().rgb)
        assert reused.camera.shadow_reuse.redrawn_whole == redrawn + 2  # the next two frames drew it whole
    finally:
        reused.close(), whole.close()


@pytest.fixture
def hairpin_worlds():
    """The two worlds of ``_worlds`` on ``hairpin`` (plain), at the start with one frame drawn; closed after."""
    track = load_track("hairpin")
    reused, whole = _worlds(track, "plain")
    try:
        for w in (reused, whole):
            w.reset(track.start_pose)
            w.render()
        yield reused, whole
    finally:
        reused.close(), whole.close()


def test_ctrl_c_in_the_middle_of_a_frame_is_raised_not_dropped(hairpin_worlds, monkeypatch):
    # A signal's handler can run inside the GL callback; ctypes would print its exception and go on.
    reused, whole = hairpin_worlds
    real = ShadowMapReuse.rect_for
    calls = []

    def interrupted(self, size):
        calls.append(size)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real(self, size)

    monkeypatch.setattr(ShadowMapReuse, "rect_for", interrupted)
    with pytest.raises(KeyboardInterrupt):
        reused.render()
    for _ in range(3):  # the env goes on as before: the next maps are drawn whole
        assert np.array_equal(reused.render().rgb, whole.render().rgb)
    # in a frame of your own, the exception comes out of PyBullet's call in your thread
    _ctrl_c_in_your_own_frame(reused, whole, monkeypatch)


def _ctrl_c_in_your_own_frame(reused, whole, monkeypatch):
    """A Ctrl-C whose handler runs in the GL callback of a ``getCameraImage`` of your own (not the env's)
    comes out of that call in your thread; then (the patches undone) the env's frames are still right."""
    hook = egl_shadow_reuse._hook
    monkeypatch.setattr(hook, "current_context", lambda: (_ for _ in ()).throw(KeyboardInterrupt()))
    reused._activate()
    view = p.computeViewMatrix([0, 0, 5], [5, 0, 0], [0, 0, 1])
    with pytest.raises(KeyboardInterrupt):
        p.getCameraImage(32, 32, view, p.computeProjectionMatrixFOV(60, 1, 0.1, 50),
                         renderer=p.ER_BULLET_HARDWARE_OPENGL, physicsClientId=reused._client)
        for _ in range(100):  # raised as soon as the call has returned
            time.sleep(0.01)
    monkeypatch.undo()
    for _ in range(3):
        assert np.array_equal(reused.render().rgb, whole.render().rgb)


def test_ctrl_c_in_your_own_frame_is_raised_however_slowly_this_thread_leaves_the_hook(hairpin_worlds, monkeypatch):
    # On a loaded machine the thread that started the helper can be slow to come back from
    # Thread.start() inside the hook; the exception must still come out of PyBullet's call, not be
    # raised (and dropped) inside the hook.
    start = threading.Thread.start

    def slow_start(self):
        start(self)
        time.sleep(0.05)  # the GIL released for 50 ms while still in the hook

    monkeypatch.setattr(threading.Thread, "start", slow_start)
    _ctrl_c_in_your_own_frame(*hairpin_worlds, monkeypatch)


def test_the_unraisable_hook_knows_its_callback_in_either_form(hairpin_worlds):
    reused, _ = hairpin_worlds
    hook = egl_shadow_reuse._hook
    ours = types.SimpleNamespace(object=hook._hooked, err_msg=None)  # Python 3.11-3.12
    named = types.SimpleNamespace(object=None, err_msg=f"Exception ignored on calling ctypes callback function "
                                                       f"{hook._hooked!r}")  # later versions
    assert hook._from_hook(ours) and hook._from_hook(named)
    for other in (types.SimpleNamespace(object=np.zeros(3), err_msg=None),
                  types.SimpleNamespace(object=None, err_msg="Exception ignored in: <generator>"),
                  types.SimpleNamespace(object=reused.render, err_msg=None)):
        assert not hook._from_hook(other)
