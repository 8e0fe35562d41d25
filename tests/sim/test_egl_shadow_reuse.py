"""EGL frames that keep the shadow map of the frame before and redraw only where something moved
(``weather_gym.sim.egl.shadow_reuse``): the frames (the camera's and the chase view's) must keep the
bytes of frames whose whole map is redrawn, through knocked cones, new looks, chase views in between
and several worlds at once; a map drawn outside the plan (a frame of your own) makes the next one whole.
It is off unless switched on, checks itself with a probe frame, and touches ``sys.unraisablehook``
only while one of its frames is in flight."""

from __future__ import annotations

import subprocess
import sys
import types

import numpy as np
import pybullet as p
import pytest

from weather_gym.core.errors import InputError
from weather_gym.sim.config import SimConfig
from weather_gym.sim.egl import shadow_reuse as egl_shadow_reuse
from weather_gym.sim.egl.shadow_reuse import ShadowMapReuse, light_basis, texel_rect
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


@pytest.fixture
def reuse_on(monkeypatch):
    """Shadow-map reuse switched on for one test, from a fresh start; the GL table given back after."""
    if egl_shadow_reuse._hook is not None:  # this process's hook (the suite runs with the reuse on)
        egl_shadow_reuse._hook._entry.release()  # points itself back at its next frame
    monkeypatch.setattr(egl_shadow_reuse, "_hook", None)
    monkeypatch.setattr(egl_shadow_reuse, "_reason", None)
    monkeypatch.setenv("WEATHER_GYM_SHADOW_MAP_REUSE", "1")
    yield
    if egl_shadow_reuse._hook is not None:
        egl_shadow_reuse._hook._entry.release()


@pytest.mark.parametrize("value", [None, "0", ""])
def test_it_is_off_unless_switched_on(value, monkeypatch):
    monkeypatch.setattr(egl_shadow_reuse, "_hook", None)
    monkeypatch.setattr(egl_shadow_reuse, "_reason", None)
    if value is None:
        monkeypatch.delenv("WEATHER_GYM_SHADOW_MAP_REUSE", raising=False)
    else:
        monkeypatch.setenv("WEATHER_GYM_SHADOW_MAP_REUSE", value)
    assert egl_shadow_reuse.unavailable_reason().startswith("off (the default; WEATHER_GYM_SHADOW_MAP_REUSE=1")
    assert egl_shadow_reuse._hook is None


def test_a_switch_that_is_neither_on_nor_off_is_refused(monkeypatch):
    monkeypatch.setattr(egl_shadow_reuse, "_hook", None)
    monkeypatch.setattr(egl_shadow_reuse, "_reason", None)
    monkeypatch.setenv("WEATHER_GYM_SHADOW_MAP_REUSE", "yes")
    with pytest.raises(InputError, match="WEATHER_GYM_SHADOW_MAP_REUSE must be 1 .* or 0 .*got 'yes'"):
        egl_shadow_reuse.unavailable_reason()


DEFAULT_FRAME = """
import sys
from weather_gym.sim.egl import shadow_reuse as egl_shadow_reuse
from weather_gym.sim.egl.gl_table import _proc_address
from weather_gym.sim.egl.elf_symbols import loaded_symbol
from weather_gym.sim.renderer import _egl_plugin_path
from weather_gym.sim.world import World
from weather_gym.tracks import load_track
import ctypes
track = load_track("hairpin")
world = World(track)
world.reset(track.start_pose)
for _ in range(3):
    world.step(0.0, 0.5)
    world.render()
    assert sys.unraisablehook is sys.__unraisablehook__
if world.renderer_name == "egl":
    _, slot, _ = loaded_symbol(_egl_plugin_path(), "glad_glViewport", "PyBullet's EGL plugin")
    assert ctypes.c_uint64.from_address(slot).value == _proc_address("glViewport"), "the table was written"
assert egl_shadow_reuse._hook is None
print(world.renderer_name)
world.close()
"""


def test_the_default_frames_patch_nothing(monkeypatch):
    # a fresh process: its default world's frames leave the plugin's GL table and sys.unraisablehook alone
    monkeypatch.delenv("WEATHER_GYM_SHADOW_MAP_REUSE", raising=False)
    out = subprocess.run([sys.executable, "-c", DEFAULT_FRAME], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    if out.stdout.split()[-1] != "egl":
        pytest.skip("EGL does not load here")


@pytest.mark.usefixtures("reuse_on")
def test_an_unverified_pybullet_build_leaves_it_off(monkeypatch):
    monkeypatch.setattr(egl_shadow_reuse, "version", lambda name: "9.9.9")
    assert egl_shadow_reuse.unavailable_reason() == ("PyBullet 9.9.9 is not a build this was verified on "
                                                     f"({', '.join(egl_shadow_reuse.VERIFIED_BUILDS)})")
    assert egl_shadow_reuse._hook is None


@pytest.mark.usefixtures("reuse_on")
def test_a_probe_frame_that_differs_switches_it_off(monkeypatch):
    # a scissor on the wrong texels (here: none at all, as another map size or light basis could give)
    track = load_track("hairpin")
    world = World(track)
    try:
        if world.renderer_name != "egl":
            pytest.skip("EGL does not load here")
        monkeypatch.setattr(ShadowMapReuse, "rect_for",
                            lambda self, size: None if self._spheres is None else (0, 0, 0, 0))
        reason = egl_shadow_reuse.unavailable_reason()
        if reason is not None and not reason.startswith("switched off"):
            pytest.skip(f"no shadow-map reuse here: {reason}")
        assert reason is not None and reason.startswith("switched off: a probe frame differs from the whole-map frame")
        assert egl_shadow_reuse._hook is None
        world.reset(track.start_pose)
        world.render()  # drawn as the plugin draws it
        assert world.camera.shadow_reuse.redrawn_whole == 0
    finally:
        world.close()


def _worlds(track, scene):
    """Two worlds, the first reusing its shadow maps (the test switches reuse on), the second not."""
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
@pytest.mark.usefixtures("reuse_on")
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
@pytest.mark.usefixtures("reuse_on")
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


@pytest.mark.usefixtures("reuse_on")
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
def hairpin_worlds(reuse_on):
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


@pytest.mark.usefixtures("reuse_on")
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
    before = sys.unraisablehook
    with pytest.raises(KeyboardInterrupt):
        reused.render()
    for _ in range(3):  # the env goes on as before: the next maps are drawn whole
        assert np.array_equal(reused.render().rgb, whole.render().rgb)
    assert sys.unraisablehook is before  # put back once the frame was over


@pytest.mark.usefixtures("reuse_on")
def test_the_unraisable_hook_is_replaced_only_while_a_frame_is_in_flight(hairpin_worlds, monkeypatch):
    reused, _ = hairpin_worlds
    seen = []
    real = ShadowMapReuse.rect_for

    def watching(self, size):
        seen.append(sys.unraisablehook)
        return real(self, size)

    monkeypatch.setattr(ShadowMapReuse, "rect_for", watching)
    before = sys.unraisablehook
    reused.step(0.0, 0.5)
    reused.render()
    assert seen and all(h == egl_shadow_reuse._hook._on_unraisable for h in seen)
    assert sys.unraisablehook is before


@pytest.mark.usefixtures("reuse_on")
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
