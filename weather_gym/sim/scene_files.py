"""The textured mesh files of a world's ground: the plain ground (its texture drawn from the track),
the realistic scene's run-off, asphalt strip and trackside clutter. Each is made once per process for
its key (track geometry, extent, look) and shared by every world of the same track.

Example:
    >>> from weather_gym.tracks import load_track
    >>> track = load_track("small_track")
    >>> key = track_key(track)
    >>> len(key), key == track_key(load_track("small_track"))
    (4, True)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from weather_gym.sim import scenery
from weather_gym.sim.look import Look
from weather_gym.sim.mesh_files import mesh_file
from weather_gym.sim.meshes import quad_obj
from weather_gym.sim.scenery_textures import asphalt_tile, clutter_atlas, runoff_tile
from weather_gym.sim.textures import ground_texture

GROUND_TEXTURE_PX = 2048
"""Side of the plain ground's texture (pixels)."""


_GROUND_FILES: dict[tuple, Path] = {}
"""(track geometry, extent, ground look) -> ground mesh file: worlds of the same track share it."""


def ground_file(track, extent: tuple[float, float, float, float], look: Look) -> Path:
    """The ground's textured mesh file for ``track`` under ``look`` (texture made once per process)."""
    geometry = tuple(np.ascontiguousarray(a, dtype=np.float64).tobytes()
                     for a in (track.centerline, track.half_width_left, track.half_width_right))
    key = (geometry, bool(track.closed), extent, look.asphalt_rgb, look.grass_rgb, look.kerb_rgb, look.ground_seed)
    path = _GROUND_FILES.get(key)
    if path is None or not path.exists():
        tex = ground_texture(np.asarray(track.centerline), np.asarray(track.half_width_left),
                             np.asarray(track.half_width_right), bool(track.closed), extent, look,
                             size=GROUND_TEXTURE_PX)
        path = mesh_file("ground", quad_obj(*extent), tex)
        if len(_GROUND_FILES) >= 64:
            _GROUND_FILES.pop(next(iter(_GROUND_FILES)))
        _GROUND_FILES[key] = path
    return path


_REALISTIC_FILES: dict[tuple, Path] = {}


def _cached_file(key: tuple, make) -> Path:
    """A content-named mesh file made once per process for ``key`` (bounded: oldest dropped)."""
    path = _REALISTIC_FILES.get(key)
    if path is None or not path.exists():
        path = make()
        if len(_REALISTIC_FILES) >= 256:
            _REALISTIC_FILES.pop(next(iter(_REALISTIC_FILES)))
        _REALISTIC_FILES[key] = path
    return path


def track_key(track) -> tuple:
    return tuple(np.ascontiguousarray(a, dtype=np.float64).tobytes()
                 for a in (track.centerline, track.half_width_left, track.half_width_right)) + (bool(track.closed),)


def realistic_ground_files(track, extent: tuple[float, float, float, float], look: Look) -> list[Path]:
    """The realistic ground: a run-off quad (grass / gravel / paved, tiled) and the asphalt strip
    along the track (tiled, with patches and painted lines)."""
    x0, y0, x1, y1 = extent
    runoff = _cached_file(("runoff", extent, look.grass_rgb, look.ground_seed), lambda: mesh_file(
        "runoff", quad_obj(x0, y0, x1, y1, uv_repeat=(x1 - x0) / scenery.RUNOFF_TILE_M),
        runoff_tile(look.grass_rgb, look.ground_seed)))
    strip = _cached_file(("asphalt", track_key(track), look.asphalt_rgb, look.ground_seed), lambda: mesh_file(
        "asphalt", scenery.asphalt_strip_obj(track), asphalt_tile(look.asphalt_rgb, look.ground_seed)))
    return [runoff, strip]


def clutter_file(track, layout: int) -> Path:
    return _cached_file(("clutter", track_key(track), int(layout)), lambda: mesh_file(
        "clutter", scenery.clutter_obj(scenery.clutter_layout(track, int(layout))), clutter_atlas(0)))
