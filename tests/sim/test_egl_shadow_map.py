"""``SimConfig.shadows`` with each renderer: PyBullet's EGL plugin draws its shadow map unless told
not to (``shadows=False``, switched around each frame), TinyRenderer only when asked."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError
from weather_gym.sim.config import SimConfig
from weather_gym.sim.egl import shadow_map as egl_shadow_map
from weather_gym.sim.world import World
from weather_gym.tracks import load_track

CAMERA = CameraConfig(width=192, height=108)


def _frames(shadows, renderer="auto", n=3):
    """``n`` frames along small_track's start straight, and the renderer that drew them."""
    track = load_track("small_track")
    w = World(track, camera=CAMERA, sim=SimConfig(shadows=shadows, renderer=renderer))
    try:
        x, y, yaw = track.start_pose
        frames = []
        for i in range(n):
            w.reset((x + 2.0 * i * np.cos(yaw), y + 2.0 * i * np.sin(yaw), yaw))
            frames.append(w.render().rgb)
        return frames, w.renderer_name
    finally:
        w.close()


def _same(a, b):
    return all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def test_egl_frames_without_the_shadow_map_differ_repeat_and_leave_other_frames_alone():
    default, renderer = _frames(None)
    if renderer != "egl":
        pytest.skip("EGL does not load here")
    if (reason := egl_shadow_map.unavailable_reason()) is not None:
        pytest.skip(f"no shadow-map switch here: {reason}")
    assert _same(_frames(True)[0], default)  # the plugin's own way is its shadow map
    bare = _frames(False)[0]
    assert not _same(bare, default)
    assert _same(_frames(False)[0], bare)  # same seed, same bytes
    assert _same(_frames(None)[0], default)  # the plugin's setting was put back


def test_tinyrenderer_draws_shadows_only_when_asked():
    default, renderer = _frames(None, renderer="tiny", n=1)
    assert renderer == "tiny"
    assert _same(_frames(False, renderer="tiny", n=1)[0], default)
    assert not _same(_frames(True, renderer="tiny", n=1)[0], default)


def test_shadows_false_with_egl_is_a_clear_error_where_the_switch_is_missing(monkeypatch):
    if _frames(None, n=1)[1] != "egl":
        pytest.skip("EGL does not load here")
    monkeypatch.setattr(egl_shadow_map, "unavailable_reason", lambda: "a stripped build of the plugin")
    with pytest.raises(RuntimeError, match=r"SimConfig.shadows=False .*a stripped build.*renderer='tiny'"):
        _frames(False, n=1)


@pytest.mark.parametrize("value", ["no", 0, 1.0])
def test_shadows_must_be_a_bool_or_unset(value):
    with pytest.raises(InputError, match=r"SimConfig.shadows must be true or false or None, got"):
        SimConfig(shadows=value)
