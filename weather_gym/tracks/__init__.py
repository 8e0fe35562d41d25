"""Cone tracks: the EUFS layouts shipped in ``tracks/``, an oval, seeded random tracks, user CSV files.

A :class:`Track` holds the cones (class ids index :data:`CONE_CLASSES`) and a centerline in the
driving direction (blue cones on the left), with its half widths, the start pose and where a lap
or run is complete. Files use the Formula Student simulators' cone CSV
(``tag,x,y[,direction,x_variance,y_variance,xy_covariance]``), see ``tracks/README.md``.

Arc length ``s`` runs along the centerline from its first point. Closed tracks start at the
start/finish line (``start_line_s = 0``, ``finish_s = length``) and the start pose sits a few
metres before it. Open tracks (acceleration, skidpad) begin 5 m behind the start pose; the
timing line is at ``start_line_s`` and the run is complete at ``finish_s``.

Example:
    >>> from weather_gym.tracks import load_track
    >>> t = load_track("small_track")
    >>> t.event, t.closed, round(t.length)
    ('trackdrive', True, 150)
    >>> p = t.project(*t.point_at(30.0)[:2])
    >>> round(float(p.s), 3), round(float(p.lateral), 3)
    (30.0, 0.0)
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.core.paths import data_dir
from weather_gym.core.registry import Registry
from weather_gym.tracks import _geometry as geo
from weather_gym.tracks import _layout as layout
from weather_gym.tracks._csv import (
    DUPLICATE_TOL_M,
    MAX_CONES,
    MAX_COORDINATE_M,
    MAX_TRACK_FILE_BYTES,
    read_cone_csv,
    track_from_csv,
)
from weather_gym.tracks._track import CSV_HEADER, EVENTS, MIN_RADIUS_M, Projection, StartPose, Track

__all__ = [
    "CONE_CLASSES", "CSV_HEADER", "DUPLICATE_TOL_M", "EVENTS", "MAX_CONES", "MAX_COORDINATE_M", "MAX_TRACK_FILE_BYTES",
    "MIN_RADIUS_M", "MIRROR_PREFIX", "REVERSE_PREFIX", "TRACKS", "Projection", "StartPose", "Track",
    "generate_random_track", "is_track_file", "load_track", "mirror_track", "oval", "read_cone_csv", "reverse_track",
    "source_label", "split_track_specs", "track_file_part", "track_from_csv", "track_label",
]


# ---------------------------------------------------------------------------------------------- generated


def _check_range(what: str, value, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InputError(f"{what} must be a number in [{lo}, {hi}]; got {value!r}")
    if not lo <= float(value) <= hi:
        raise InputError(f"{what} must be in [{lo}, {hi}]; got {value!r}")
    return float(value)


def oval(straight: float = 40.0, radius: float = 15.0, width: float = 3.5, spacing: float | None = None) -> Track:
    """A counter-clockwise stadium oval: two straights joined by half circles (blue cones inside).

    Example:
        >>> round(oval().length, 1)
        174.2
    """
    straight = _check_range("oval straight", straight, 0.0, 500.0)
    radius = _check_range("oval radius", radius, MIN_RADIUS_M, 200.0)
    width = _check_range("oval width", width, 2.0, 10.0)
    if spacing is not None:
        spacing = _check_range("oval spacing", spacing, 1.0, 10.0)
    half = straight / 2.0
    arc = np.linspace(-np.pi / 2, np.pi / 2, 181)
    pts = np.concatenate([
        np.column_stack([np.linspace(0.0, half, 50, endpoint=False), np.full(50, -radius)]),
        np.column_stack([half + radius * np.cos(arc), radius * np.sin(arc)])[:-1],
        np.column_stack([np.linspace(half, -half, 100, endpoint=False), np.full(100, radius)]),
        np.column_stack([-half - radius * np.cos(arc), -radius * np.sin(arc)])[:-1],
        np.column_stack([np.linspace(-half, 0.0, 50, endpoint=False), np.full(50, -radius)]),
    ])
    line = geo.resample(pts, closed=True)
    args = f"straight={straight:g}, radius={radius:g}, width={width:g}, spacing={spacing}"
    return Track(name="oval", source=f"generated:oval({args})", **layout.ring_layout(line, width, spacing, MIN_RADIUS_M))


def generate_random_track(seed: int, *, length: float | None = None, width: float | None = None,
                          spacing: float | None = None, start_pair: float | None = None) -> Track:
    """A random closed track: same seed and arguments, same bytes.

    ``length`` (m, default: drawn in [150, 400]) and ``width`` (default: drawn in [3, 4]) come
    from their own child streams of ``SeedSequence(seed)``, so fixing one leaves the others as
    they were. Cone spacing: ``spacing`` metres, or 4.5 m on straights tightening to 3.5 m in
    the tightest corners. The centerline radius stays >= 7 m (so >= :data:`MIN_RADIUS_M`), the
    track never comes within ``width + 3`` m of itself, and the start line is on its straightest part,
    marked by one big orange cone per side or, with ``start_pair``, by two ``start_pair`` metres apart.
    As a track spec: ``"random:SEED"`` or with arguments, ``"random:SEED,start_pair=0.3,width=3.5"``.

    Example:
        >>> t = generate_random_track(3)
        >>> t.source, t.event
        ('generated:random(seed=3)', 'trackdrive')
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"random track seed must be a non-negative integer; got {seed!r}")
    if length is not None:
        length = _check_range("random track length", length, 100.0, 1000.0)
    if width is not None:
        width = _check_range("random track width", width, 2.0, 8.0)
    if spacing is not None:
        spacing = _check_range("random track spacing", spacing, 1.0, 10.0)
    if start_pair is not None:
        start_pair = _check_range("random track start_pair", start_pair, 0.2, 3.0)
    return _random_track(int(seed), length, width, spacing, start_pair)


@functools.lru_cache(maxsize=32)
def _random_track(seed: int, length: float | None, width: float | None, spacing: float | None,
                  start_pair: float | None = None) -> Track:
    r_len, r_width, r_shape = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
    length_m = float(r_len.uniform(150.0, 400.0)) if length is None else length
    width_m = float(r_width.uniform(3.0, 4.0)) if width is None else width
    line = geo.random_centerline(r_shape, length_m, min_radius=MIN_RADIUS_M + 1.0, clearance=width_m + 3.0)
    i0 = geo.straightest_index(line, closed=True)
    line = geo.resample(line, closed=True, start_s=float(geo.cumulative_length(line, True)[0][i0]))
    extras = "".join(f", {k}={v:g}" for k, v in (("length", length), ("width", width), ("spacing", spacing),
                                                  ("start_pair", start_pair)) if v is not None)
    return Track(name="random", source=f"generated:random(seed={seed}{extras})",
                 **layout.ring_layout(line, width_m, spacing, MIN_RADIUS_M, start_pair))


# ------------------------------------------------------------------------------------ reversed, mirrored

REVERSE_PREFIX = "reverse:"
"""A track spec ``"reverse:SPEC"`` is the closed track ``SPEC`` driven the other way round."""
MIRROR_PREFIX = "mirror:"
"""A track spec ``"mirror:SPEC"`` is the closed track ``SPEC`` reflected across its x axis."""
_SWAP_BLUE_YELLOW = np.array([layout.YELLOW, layout.BLUE, *range(2, len(CONE_CLASSES))], dtype=np.int64)


def _closed_only(track: Track, prefix: str, what: str) -> None:
    if not track.closed:
        raise InputError(f"track {track.name!r} is an open {track.event} track: only a closed loop can be "
                         f"{what} ('{prefix}...')")


def reverse_track(track: Track) -> Track:
    """The closed ``track`` driven the other way round: the same cones, blue and yellow swapped (blue
    stays on the driver's left), the same start line; the start pose as far before the line, in the
    new direction, as the original's is before it. As a track spec: ``"reverse:SPEC"`` (any closed
    track spec: ``"reverse:peanut"``, ``"reverse:random:7"``, ``"reverse:my_track.csv"``).

    Example:
        >>> t = load_track("small_track"); r = reverse_track(t)
        >>> r.name, r.closed, abs(r.length - t.length) < 0.5 * t.length / len(t.centerline)
        ('reverse:small_track', True, True)
        >>> bool((r.cone_classes[t.cone_classes == 0] == 1).all())   # the blue cones are yellow now
        True
    """
    _closed_only(track, REVERSE_PREFIX, "driven the other way round")
    classes = _SWAP_BLUE_YELLOW[track.cone_classes]
    behind = (track.start_line_s - float(track.project(*track.start_pose[:2]).s)) % track.length
    x, y, _ = track.point_at(track.start_line_s + behind)
    where = f"track '{REVERSE_PREFIX}{track.name}'"
    fields = layout.layout_from_cones(np.asarray(track.cones_xy), classes, (x, y, None), where)
    return Track(name=f"{REVERSE_PREFIX}{track.name}", cones_xy=track.cones_xy, cone_classes=classes,
                 source=f"reversed:{track.source}", **fields)


def mirror_track(track: Track) -> Track:
    """The closed ``track`` reflected across its x axis, driven the same way: every left turn a right
    turn, blue and yellow swapped (blue stays on the driver's left), the start pose reflected. A layout
    nobody drove, for testing a driver's turns both ways. As a track spec: ``"mirror:SPEC"``.

    Example:
        >>> t = load_track("hairpin"); m = mirror_track(t)
        >>> m.name, round(m.length, 1) == round(t.length, 1), float(m.cones_xy[0, 1]) == -float(t.cones_xy[0, 1])
        ('mirror:hairpin', True, True)
    """
    _closed_only(track, MIRROR_PREFIX, "mirrored")
    xy = np.asarray(track.cones_xy) * np.array([1.0, -1.0])
    x, y, yaw = track.start_pose
    where = f"track '{MIRROR_PREFIX}{track.name}'"
    classes = _SWAP_BLUE_YELLOW[track.cone_classes]
    fields = layout.layout_from_cones(xy, classes, (x, 0.0 - y, 0.0 - yaw), where)  # 0.0 - v: no -0.0
    return Track(name=f"{MIRROR_PREFIX}{track.name}", cones_xy=xy, cone_classes=classes,
                 source=f"mirrored:{track.source}", **fields)


_TRANSFORMS = {REVERSE_PREFIX: reverse_track, MIRROR_PREFIX: mirror_track}


@functools.lru_cache(maxsize=32)
def _transformed(prefix: str, spec: str) -> Track:
    return _TRANSFORMS[prefix](load_track(spec))


# ---------------------------------------------------------------------------------------------- registry

TRACKS: Registry = Registry("track")
"""Track name -> factory(**kwargs) -> Track."""

SHIPPED: dict[str, tuple[str, str]] = {
    "acceleration": ("eufs/acceleration.csv", "acceleration"),
    "b_shape": ("eufs/B_shape_02_03_2023.csv", "trackdrive"),
    "fsds_training": ("eufs/FSDS_Training.csv", "trackdrive"),
    "hairpin": ("eufs/Hairpin_02_03_2023.csv", "trackdrive"),
    "jellybean": ("eufs/Jellybean_02_03_2023.csv", "trackdrive"),
    "peanut": ("eufs/peanut.csv", "trackdrive"),
    "skidpad": ("eufs/skidpad.csv", "skidpad"),
    "small_track": ("eufs/small_track.csv", "trackdrive"),
}
"""Shipped layouts: name -> (file under ``tracks/``, event)."""


@functools.cache
def _shipped(name: str) -> Track:
    rel, event = SHIPPED[name]
    return track_from_csv(data_dir("tracks") / rel, name=name, event=event)


for _name in SHIPPED:
    TRACKS.register(_name, functools.partial(_shipped, _name))
TRACKS.register("oval", oval)
TRACKS.register("random", generate_random_track)


def is_track_file(spec: str | os.PathLike) -> bool:
    """Whether :func:`load_track` reads ``spec`` as a cone CSV path (not a registered name or ``random:SEED``).

    Example:
        >>> is_track_file("peanut"), is_track_file("random:3"), is_track_file("my/track.csv")
        (False, False, True)
    """
    if isinstance(spec, os.PathLike):
        return True
    name = spec.strip()
    if name == "random" or name.startswith(("random:", *_TRANSFORMS)) or name in TRACKS:
        return False
    return name.lower().endswith(".csv") or "/" in name or os.sep in name or Path(name).is_file()


def track_file_part(spec) -> tuple[str, str] | None:
    """The cone CSV a string track spec reads, split off its ``reverse:`` / ``mirror:`` prefixes:
    ``(prefixes, path)``, or None when the spec reads no file (a registered name, ``random:SEED``). Where
    a spec's file is confined (a dataset, a scenario), the path is resolved and the prefixes put back.

    Example:
        >>> track_file_part("reverse:my/track.csv"), track_file_part("mirror:peanut"), track_file_part("a.csv")
        (('reverse:', 'my/track.csv'), None, ('', 'a.csv'))
    """
    if not isinstance(spec, str):
        return None
    whole = inner = spec.strip()
    while inner.startswith(tuple(_TRANSFORMS)):
        inner = inner.split(":", 1)[1].strip()
    if not inner or not is_track_file(inner):
        return None
    return whole[:len(whole) - len(inner)], inner


def track_label(spec: str | os.PathLike) -> str:
    """How a track spec is shown to people (lap printouts, report titles): the spec itself, but a
    cone CSV by its file name without the folder (a path is this machine's business).

    Example:
        >>> track_label("/home/me/tracks/test_day.csv"), track_label("reverse:data/b.csv"), track_label("random:7")
        ('test_day', 'reverse:b', 'random:7')
    """
    part = track_file_part(os.fspath(spec))
    if part is None:
        return os.fspath(spec)
    prefixes, path = part
    return prefixes + Path(path).stem


def source_label(source: str) -> str:
    """A track's ``source`` as shown by ``weather-gym tracks list``: a shipped CSV relative to the shipped
    ``tracks`` folder (``tracks/eufs/peanut.csv``, wherever the package is installed), another file by
    its name, a generated track's recipe as it is."""
    try:
        return str(Path("tracks") / Path(source).resolve().relative_to(data_dir("tracks").resolve()))
    except (ValueError, OSError):
        return Path(source).name if is_track_file(source) else source


RANDOM_TRACK_ARGS = ("length", "width", "spacing", "start_pair")
"""Keyword arguments of :func:`generate_random_track` a ``random:SEED,KEY=VALUE,...`` spec may set."""


def split_track_specs(text: str) -> tuple[str, ...]:
    """A comma-separated list of track specs (``--track``), keeping a random track's ``KEY=VALUE``
    arguments with their spec: an item that holds ``=`` belongs to the spec before it.

    Example:
        >>> split_track_specs("peanut, random:1,width=2.5,length=200 ,reverse:random:2,width=2.8")
        ('peanut', 'random:1,width=2.5,length=200', 'reverse:random:2,width=2.8')
    """
    out: list[str] = []
    for item in (part.strip() for part in str(text).split(",")):
        if not item:
            continue
        if "=" in item and out:
            out[-1] = f"{out[-1]},{item}"
        else:
            out.append(item)
    return tuple(out)


def _random_args(spec: str, args: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in args:
        key, eq, raw = (part.strip() for part in item.partition("="))
        if not eq or key not in RANDOM_TRACK_ARGS:
            raise InputError(f"track {spec!r}: expected KEY=VALUE with KEY in {', '.join(RANDOM_TRACK_ARGS)} after "
                             f"'random:SEED,', got {item!r}")
        try:
            out[key] = float(raw)
        except ValueError:
            raise InputError(f"track {spec!r}: {key} must be a number (metres), got {raw!r}") from None
    return out


def load_track(spec: str | os.PathLike | Track, *, seed: int | None = None, event: str | None = None) -> Track:
    """A track from a registered name, ``"random:SEED"`` (or ``"random"`` with ``seed=``), a CSV path,
    ``"reverse:SPEC"`` (:func:`reverse_track`), ``"mirror:SPEC"`` (:func:`mirror_track`) or a :class:`Track`
    (returned as is). ``seed`` only matters for ``"random"``; ``"random:SEED"`` keeps its own seed.
    ``event`` applies to CSV files (see :func:`track_from_csv`).

    Example:
        >>> load_track("random:7").source
        'generated:random(seed=7)'
        >>> load_track("reverse:random:7").source
        'reversed:generated:random(seed=7)'
    """
    if isinstance(spec, Track):
        return spec
    if isinstance(spec, os.PathLike):
        return track_from_csv(spec, event=event)
    if not isinstance(spec, str):
        raise InputError(f"track spec must be a track name, 'random:SEED', a CSV path or a Track; got {spec!r}")
    name = spec.strip()
    for prefix, transform in _TRANSFORMS.items():
        if name.startswith(prefix):
            if event not in (None, "trackdrive"):
                raise InputError(f"track {spec!r} is a trackdrive track (a closed loop), not {event!r}")
            inner = name[len(prefix):].strip()
            if not inner:
                raise InputError(f"track {spec!r}: '{prefix}' needs a track spec after it, e.g. '{prefix}peanut'")
            return _transformed(prefix, inner) if seed is None else transform(load_track(inner, seed=seed))
    if name == "random" or name.startswith("random:"):
        kwargs: dict[str, float] = {}
        if ":" in name:
            raw, *args = name.split(":", 1)[1].split(",")
            try:
                seed = int(raw)
            except ValueError:
                raise InputError(f"track {spec!r}: 'random:SEED' needs an integer seed, got {raw!r}") from None
            kwargs = _random_args(spec, args)
        elif seed is None:
            raise InputError("track 'random' needs a seed: use 'random:SEED' or load_track('random', seed=SEED)")
        return generate_random_track(seed, **kwargs)
    if name in TRACKS:
        track = TRACKS.get(name)()
        if event is not None and event != track.event:
            raise InputError(f"track {name!r} is a {track.event} track, not {event!r}")
        return track
    if is_track_file(name):
        return track_from_csv(name, event=event)
    raise InputError(f"unknown track {name!r}; valid names: {', '.join(TRACKS.names())}, "
                     "'random:SEED', 'reverse:SPEC', 'mirror:SPEC', or a path to a cone CSV file")
