"""Cast shadows of the realistic world's cones: the ground geometry, its projection into the frame,
and rendered frames (darker ground beyond a cone, away from the sun; the cone itself untouched)."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError
from weather_gym.sim.cast_shadows import (
    MAX_SHADOW_M,
    ShadowCaster,
    camera_rotation,
    clip_near,
    ground_depth_band,
    shadow_polygons,
    shadow_strength,
)
from weather_gym.sim.config import SimConfig


def _sun(elevation_deg: float, azimuth_deg: float) -> tuple[float, float, float]:
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e))


@pytest.mark.parametrize("elevation", [8.0, 20.0, 35.0, 60.0])
@pytest.mark.parametrize("azimuth", [0.0, 30.0, 45.0, 100.0, 225.0, 300.0])
def test_shadow_points_away_from_the_sun_with_length_h_cot_e(elevation, azimuth):
    h, half, centre = 0.505, 0.1425, np.array([3.0, -2.0])
    poly = shadow_polygons(centre[None], np.array([half]), np.array([h]), _sun(elevation, azimuth))
    assert poly.shape == (1, 4, 2)
    tip = poly[0, 0] - centre
    assert np.hypot(*tip) == pytest.approx(min(h / math.tan(math.radians(elevation)), MAX_SHADOW_M), rel=1e-9)
    away = -np.array(_sun(elevation, azimuth)[:2])
    assert float(tip @ away) / (np.hypot(*tip) * np.hypot(*away)) == pytest.approx(1.0, abs=1e-9)
    # the polygon is the hull of plate and tip's shadow less the plate: areas add up, no overlap
    square = centre + half * np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], dtype=np.float64)
    hull = cv2.convexHull(np.concatenate([square, poly[0, :1]]).astype(np.float32))
    area = abs(cv2.contourArea(poly[0].astype(np.float32)))
    assert area + (2 * half) ** 2 == pytest.approx(cv2.contourArea(hull), rel=1e-4)
    assert all(cv2.pointPolygonTest(poly[0].astype(np.float32), (float(x), float(y)), False) <= 0
               for x, y in centre + 0.99 * (square - centre))  # the plate's corners are not inside


def test_no_shadow_for_a_high_sun_or_a_sun_below_the_horizon_and_long_ones_are_capped():
    xy, half, h = np.zeros((2, 2)), np.full(2, 0.114), np.array([0.325, 0.325])
    assert len(shadow_polygons(xy, half, h, _sun(80.0, 10.0))) == 0  # the tip's shadow falls on the plate
    assert len(shadow_polygons(xy, half, h, _sun(-5.0, 10.0))) == 0
    assert len(shadow_polygons(xy, half, h, (0.0, 0.0, 1.0))) == 0
    poly = shadow_polygons(xy, half, h, _sun(1.0, 10.0), max_length=2.5)
    assert len(poly) == 2 and np.hypot(*poly[0, 0]) == pytest.approx(2.5)


def test_strength_follows_the_share_of_direct_light():
    assert shadow_strength(0.6, 0.45) == pytest.approx(0.45 / 1.05)
    assert shadow_strength(0.9, 0.01) == 0.1 and shadow_strength(0.1, 0.9) == 0.6


def test_clip_near_keeps_the_part_in_front():
    poly = np.array([[0.0, 1.0, -1.0], [1.0, 1.0, 3.0], [-1.0, 1.0, 3.0]])
    out = clip_near(poly, 0.5)
    assert len(out) == 4 and (out[:, 2] >= 0.5 - 1e-12).all()
    assert len(clip_near(poly[:, :] - [0, 0, 10], 0.5)) == 0


def _ground_coverage_by_ray_casting(cam: CameraConfig, eye, heading, pitch, polys, n: int = 6) -> np.ndarray:
    """Share of each pixel whose rays (n x n per pixel) hit the ground inside one of the ground
    polygons: the reference, independent of the projection and filling under test."""
    rot = camera_rotation(heading, pitch)
    sub = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid((np.arange(cam.width)[:, None] + sub).ravel(), (np.arange(cam.height)[:, None] + sub).ravel())
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], axis=-1) @ rot
    ok = rays[..., 2] < -1e-9
    t = np.where(ok, -eye[2] / np.where(ok, rays[..., 2], -1.0), 0.0)
    gx, gy = eye[0] + t * rays[..., 0], eye[1] + t * rays[..., 1]
    hit = np.zeros(u.shape, bool)
    for poly in polys:
        inside = np.zeros(u.shape, bool)
        for i in range(len(poly)):  # even-odd crossing test
            (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % len(poly)]
            if y0 == y1:
                continue
            inside ^= ((y0 > gy) != (y1 > gy)) & (gx < (x1 - x0) * (gy - y0) / (y1 - y0) + x0)
        hit |= inside & ok
    return hit.reshape(cam.height, n, cam.width, n).mean(axis=(1, 3))


@pytest.mark.parametrize("case", ["ahead", "beside_and_behind", "off_centre_camera"])
def test_mask_matches_ray_cast_ground_and_spares_what_is_not_ground(case):
    """The projected, filled shadows cover the pixels whose rays hit the shadow on the ground (up to
    the edge pixels), also for a cone behind and beside the camera whose shadow reaches forward
    (clipped at the near plane) and for measured intrinsics; a pixel showing anything else (not the
    ground's depth) is untouched."""
    if case == "off_centre_camera":
        cam = CameraConfig.from_intrinsics(160, 90, 100.0, 96.0, 70.0, 50.0, mount_height=1.0, pitch_deg=6.0)
        assert not cam.centred
    else:
        cam = CameraConfig(width=160, height=90, mount_height=1.0, pitch_deg=6.0)
    eye, heading, pitch = np.array([0.0, 0.0, 1.0]), 0.0, math.radians(6.0)
    if case != "beside_and_behind":
        xy, sun = np.array([[4.0, 0.5], [7.0, -1.5], [-3.0, 0.0]]), _sun(12.0, 150.0)
    else:  # behind-left of the camera, the sun behind it: the shadow runs forward past the camera
        xy, sun = np.array([[-0.4, 0.9], [-1.0, -0.6]]), _sun(6.0, 180.0)
    half, h = np.full(len(xy), 0.1425), np.full(len(xy), 0.505)
    polys = shadow_polygons(xy, half, h, sun)
    caster = ShadowCaster(cam)
    image_polys = caster.image_polygons(eye, heading, pitch, xy, half, h, sun)
    assert image_polys and all(np.isfinite(p).all() for p in image_polys)
    lo, hi = ground_depth_band(cam, 1.0, pitch)
    ground = np.isfinite(lo)
    depth = np.where(ground, (np.where(ground, lo, 0) + np.where(ground, hi, 0)) / 2, cam.far)
    depth = np.repeat(depth[:, None], cam.width, axis=1).astype(np.float32)
    depth[:, :10] = 2.0  # something standing on the ground, in front of it
    rgb = np.full((cam.height, cam.width, 3), 200, np.uint8)
    caster.apply(rgb, depth, eye, heading, pitch, xy, half, h, sun, 0.5)
    cover = (200.0 - rgb[..., 0]) / 100.0  # strength 0.5 on a level of 200
    ref = _ground_coverage_by_ray_casting(cam, eye, heading, pitch, polys)
    ref[:, :10] = 0.0
    assert ref.sum() > 30
    assert np.abs(cover - ref).max() < 0.3  # every pixel
    assert cover.sum() == pytest.approx(ref.sum(), rel=0.08)  # the shadows' area in pixels
    assert (rgb[:, :10] == 200).all()
    inner = cover[ref == 1.0]  # strength 0.5 where fully covered (an edge's samples count half)
    assert (inner >= 0.85).all() and np.median(inner) == 1.0
    again = np.full_like(rgb, 200)
    caster.apply(again, depth, eye, heading, pitch, xy, half, h, sun, 0.5)
    assert np.array_equal(again, rgb)  # same inputs, same bytes


def test_ground_depth_band_is_empty_above_the_horizon():
    cam = CameraConfig(width=64, height=48, pitch_deg=0.0)
    lo, hi = ground_depth_band(cam, 1.0, 0.0)
    top, bottom = slice(0, 24), slice(24, 48)
    assert (lo[top] > hi[top]).all() and (lo[bottom] < hi[bottom]).all()
    # the last row looks down at atan(23.5 / fy) below the horizon
    g = 1.0 / ((47.5 - cam.cy) / cam.fy)
    assert lo[-1] < g < hi[-1]


def test_cast_shadows_must_be_a_bool():
    with pytest.raises(InputError, match="cast_shadows"):
        SimConfig(cast_shadows="yes")


# ----------------------------------------------------------------------------------- rendered frames
@pytest.fixture(scope="module")
def facing_cone():
    """A realistic world (with and without cast shadows) whose camera looks straight at cone 0 from
    4 m, and where that cone's pixels and the ground beside it lie."""
    from weather_gym.sim.look import REALISTIC_LOOK
    from weather_gym.sim.world import World
    from weather_gym.tracks import load_track

    track = load_track("small_track")
    cam = CameraConfig(width=336, height=188)
    look = replace(REALISTIC_LOOK, ego_seed=-1)
    worlds = {on: World(track, sim=SimConfig(scene="realistic", cast_shadows=on), camera=cam, look=look)
              for on in (True, False)}
    cone = worlds[True]._cone_home[0]
    heading = 0.3
    pose = (float(cone[0] - 4.6 * math.cos(heading)), float(cone[1] - 4.6 * math.sin(heading)), heading)
    for w in worlds.values():
        w.reset(pose)
    yield worlds, heading
    for w in worlds.values():
        w.close()


def _frame(world, look_kw):
    world.set_look(replace(world.look, **look_kw))
    return world.render()


def _sides(frame, ref):
    """The darkest row's brightness relative to frame ``ref`` in the ground just left / right of cone
    0's base (1: unchanged), and the cone's pixel mask."""
    mask = frame.segmentation == 0
    ys, xs = np.nonzero(mask)
    rows = slice(int(ys.max()) - 8, int(ys.max()) + 3)
    g, g0 = (f.rgb.astype(np.float64).sum(axis=2) for f in (frame, ref))
    left, right = slice(int(xs.min()) - 30, int(xs.min()) - 2), slice(int(xs.max()) + 3, int(xs.max()) + 31)
    ratio = [(g[rows, c].mean(axis=1) / g0[rows, c].mean(axis=1)).min() for c in (left, right)]
    return ratio[0], ratio[1], mask


@pytest.mark.slow
def test_rendered_shadow_darkens_the_ground_away_from_the_sun_only(facing_cone):
    worlds, heading = facing_cone
    sun_left = _sun(15.0, math.degrees(heading) + 90.0)  # low, from the camera's left: shadow to the right
    on = _frame(worlds[True], {"light_direction": sun_left})
    off = _frame(worlds[False], {"light_direction": sun_left})
    assert np.array_equal(on.segmentation, off.segmentation) and np.array_equal(on.depth, off.depth)
    left, right, mask = _sides(on, off)
    strength = shadow_strength(worlds[True].look.ambient, worlds[True].look.diffuse)
    assert right < 1 - 0.8 * strength  # the ground right of the cone: in its shadow
    assert left > 0.995  # the sunny side: as rendered
    # the cone is not darkened: only pixels of its lowest centimetre (the base plate's foot, which
    # the depth test cannot tell from the ground) may change
    changed = (on.rgb != off.rgb).any(axis=2)
    cam = worlds[True].camera_config
    eye, _, pitch = worlds[True].camera.mount_pose(worlds[True].car.pose)
    lo, hi = ground_depth_band(cam, float(eye[2]), pitch)
    ground_like = (on.depth >= lo[:, None]) & (on.depth <= hi[:, None])
    assert not (changed & ~ground_like).any()
    assert (changed & mask).sum() <= 0.02 * mask.sum()
    # the sun from the right: the shadow swaps sides
    sun_right = _sun(15.0, math.degrees(heading) - 90.0)
    left, right, _ = _sides(_frame(worlds[True], {"light_direction": sun_right}),
                            _frame(worlds[False], {"light_direction": sun_right}))
    assert left < 1 - 0.8 * strength and right > 0.995
    # a high sun: the shadow falls on the cone's own plate, nothing is drawn beside it
    high = _sun(80.0, math.degrees(heading) + 90.0)
    left, right, _ = _sides(_frame(worlds[True], {"light_direction": high}),
                            _frame(worlds[False], {"light_direction": high}))
    assert left > 0.995 and right > 0.995


@pytest.mark.slow
def test_a_knocked_over_cone_casts_no_shadow(facing_cone):
    worlds, heading = facing_cone
    w = worlds[True]
    sun_left = _sun(15.0, math.degrees(heading) + 90.0)
    off = _frame(worlds[False], {"light_direction": sun_left})
    assert _sides(_frame(w, {"light_direction": sun_left}), off)[1] < 0.8
    rot = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # lying on its side (only the shadow step reads this)
    w._cone_tilt[0] = (np.array([*w._cone_home[0], 0.0]), rot)
    try:
        lying = _frame(w, {"light_direction": sun_left})
    finally:
        w._cone_tilt.clear()
    assert _sides(lying, off)[1] > 0.995
