"""Tracks layer: shipped EUFS layouts, oval, random generator, CSV loader and its errors, CLI."""

from __future__ import annotations

import math

import numpy as np
import pytest

from weather_gym import tracks as tr
from weather_gym.tracks import (
    CONE_CLASSES,
    TRACKS,
    Track,
    generate_random_track,
    load_track,
    read_cone_csv,
)
from weather_gym.tracks import _geometry as geo

BLUE, YELLOW, ORANGE, BIG = range(4)
SHIPPED_TRACKDRIVE = ["b_shape", "fsds_training", "hairpin", "jellybean", "peanut", "small_track"]
ALL = [*tr.SHIPPED, "oval", "random:7", "reverse:small_track", "reverse:random:7", "mirror:peanut", "mirror:random:7"]


def _angle(a: float) -> float:
    return abs(math.atan2(math.sin(a), math.cos(a)))


def test_registry_has_every_named_track():
    assert set(TRACKS.names()) == {*SHIPPED_TRACKDRIVE, "acceleration", "skidpad", "oval", "random"}
    assert CONE_CLASSES == ("blue", "yellow", "orange", "big_orange")


@pytest.mark.parametrize("name", ALL)
def test_track_is_sane(name):
    t = load_track(name)
    assert t.cones_xy.dtype == np.float64 and t.cones_xy.shape == (len(t.cone_classes), 2)
    assert t.cone_classes.dtype == np.int64 and set(np.unique(t.cone_classes)) <= {0, 1, 2, 3}
    assert not t.cones_xy.flags.writeable and not t.centerline.flags.writeable
    step = np.diff(np.vstack([t.centerline, t.centerline[:1]]) if t.closed else t.centerline, axis=0)
    assert np.allclose(np.hypot(*step.T), 0.5, atol=0.05)
    # blue left, yellow right of the centerline, every single cone
    lateral = t.project(t.cones_xy[:, 0], t.cones_xy[:, 1]).lateral
    assert (lateral[t.cone_classes == BLUE] > 0.5).all()
    assert (lateral[t.cone_classes == YELLOW] < -0.5).all()
    width = t.half_width_left + t.half_width_right
    assert (t.half_width_left > 1.0).all() and (t.half_width_right > 1.0).all()
    assert 2.5 < width.min() and width.max() < 8.0
    # start pose on the centerline, facing along it, before the start line
    sp = t.project(*t.start_pose[:2])
    assert abs(sp.lateral) < 1.0 and _angle(t.start_pose[2] - sp.heading) < math.radians(30)
    if t.closed:
        assert t.event == "trackdrive" and t.start_line_s == 0.0 and t.finish_s == pytest.approx(t.length)
        assert t.length - 15.0 < sp.s < t.length
        assert not geo.self_intersects(t.centerline, closed=True)
        assert np.linalg.norm(t.centerline[-1] - t.centerline[0]) < 0.6
    else:
        assert 0.0 < sp.s < t.start_line_s < t.finish_s <= t.length + 1e-9


def test_shipped_lengths_are_the_real_layouts():
    # centerline lengths of the EUFS layouts (seen in `weather-gym tracks list`)
    lengths = {n: load_track(n).length for n in tr.SHIPPED}
    assert 370 < lengths["fsds_training"] < 395
    assert all(45 < v < 160 for n, v in lengths.items() if n in {"b_shape", "hairpin", "jellybean", "peanut",
                                                                   "small_track"})


def test_acceleration_is_75_m_straight_with_braking_zone():
    t = load_track("acceleration")
    assert t.event == "acceleration" and not t.closed
    assert t.finish_s - t.start_line_s == pytest.approx(75.0, abs=0.01)
    assert np.abs(t.curvature).max() < 1e-6
    assert np.allclose(t.half_width_left, 1.5) and np.allclose(t.half_width_right, 1.5)
    end_x = t.point_at(t.length)[0]
    assert end_x == pytest.approx(t.cones_xy[t.cone_classes == ORANGE, 0].max())  # through the braking zone
    assert t.start_pose == (-53.0, 0.0, 0.0)


def test_skidpad_sequence_and_s_hint():
    t = load_track("skidpad")
    assert t.event == "skidpad" and not t.closed
    r = 9.25  # crossing at (0, 0), circle centres at (+-9.25, 0) in the EUFS file
    entry = t.start_line_s
    assert t.point_at(entry)[:2] == pytest.approx((0.0, 0.0), abs=1e-3)
    assert t.length == pytest.approx(entry + 8 * math.pi * r + 21.0, abs=0.5)
    # right circle first (clockwise: curvature < 0), then the left one (counter-clockwise)
    assert t.curvature[np.searchsorted(t.s, entry + 2 * math.pi * r)] == pytest.approx(-1 / r, rel=0.02)
    assert t.curvature[np.searchsorted(t.s, entry + 6 * math.pi * r)] == pytest.approx(1 / r, rel=0.02)
    # (18.5, 0) is on the right circle, passed in lap 1 and lap 2: the hint picks the lap
    lap1 = entry + math.pi * r
    for hint in (lap1, lap1 + 2 * math.pi * r):
        p = t.project(18.5, 0.0, s_hint=hint)
        assert p.s == pytest.approx(hint, abs=0.05) and abs(p.lateral) < 0.01
    # a point just before the crossing: entry lane, end of the right laps, end of the left laps
    for hint in (entry, entry + 4 * math.pi * r, entry + 8 * math.pi * r):
        p = t.project(0.0, -0.5, s_hint=hint - 1.0, window=5.0)
        assert p.s == pytest.approx(hint - 0.5, abs=0.1)  # the branch, not the others 58 m away


@pytest.mark.parametrize("name", ["peanut", "oval", "skidpad", "acceleration"])
def test_project_point_at_round_trip(name):
    t = load_track(name)
    s = np.linspace(0.0, t.length, 37)[1:-1]
    x, y, h = t.point_at(s)
    hint = None
    for k in range(len(s)):
        if t.event == "skidpad":
            hint = s[k]
        p = t.project(x[k], y[k], s_hint=hint)
        assert p.s == pytest.approx(s[k], abs=1e-6) and abs(p.lateral) < 1e-9
        assert _angle(p.heading - h[k]) < 1e-6
        # step sideways: lateral is the signed offset (positive = left)
        for d in (-0.8, 0.6):
            q = t.project(x[k] - d * math.sin(h[k]), y[k] + d * math.cos(h[k]), s_hint=hint)
            assert q.lateral == pytest.approx(d, abs=0.02)
    if t.event != "skidpad":  # vectorised = scalar
        pa = t.project(x, y)
        assert np.allclose(pa.s, s) and pa.index.shape == s.shape
    left, right = t.boundary_distance(x[3], y[3], s_hint=s[3])
    assert left + right == pytest.approx(float(sum(t.half_widths_at(s[3]))))


def test_closed_track_wraps_and_open_track_extends():
    t = load_track("oval")
    assert t.point_at(t.length + 10.0) == pytest.approx(t.point_at(10.0))
    assert t.project(*t.point_at(t.length - 0.2)[:2]).s == pytest.approx(t.length - 0.2, abs=1e-6)
    a = load_track("acceleration")
    x, y, _ = a.point_at(-2.0)
    assert a.project(x, y).s == pytest.approx(-2.0)


@pytest.mark.parametrize("seed", range(20))
def test_random_track_meets_spec(seed):
    t = generate_random_track(seed)
    assert t.event == "trackdrive" and t.closed and t.source == f"generated:random(seed={seed})"
    assert 150.0 <= t.length <= 400.0
    assert 1.0 / np.abs(t.curvature).max() >= tr.MIN_RADIUS_M
    assert not geo.self_intersects(t.centerline, closed=True)
    p = t.project(t.cones_xy[:, 0], t.cones_xy[:, 1])
    width = 2.0 * np.abs(p.lateral)
    assert np.ptp(width) < 0.05 and 3.0 <= width.min() and width.max() <= 4.0
    for sign in (1, -1):  # consecutive cones along each side, big orange start cone included
        side = np.nonzero(np.sign(p.lateral) == sign)[0]
        ordered = t.cones_xy[side[np.argsort(p.s[side])]]
        gaps = np.linalg.norm(np.diff(np.vstack([ordered, ordered[:1]]), axis=0), axis=1)
        assert 3.0 <= gaps.min() and gaps.max() <= 5.0
    assert (t.cone_classes == BIG).sum() == 2


def test_random_track_is_repeatable_and_seeded():
    a = generate_random_track(11)
    tr._random_track.cache_clear()
    b = generate_random_track(11)
    assert a is not b
    for field in ("cones_xy", "cone_classes", "centerline", "half_width_left", "half_width_right"):
        assert getattr(a, field).tobytes() == getattr(b, field).tobytes()
    assert a.start_pose == b.start_pose
    c = generate_random_track(12)
    assert c.cones_xy.shape != a.cones_xy.shape or not np.array_equal(c.cones_xy, a.cones_xy)
    assert load_track("random", seed=11).centerline.tobytes() == a.centerline.tobytes()
    short = generate_random_track(11, length=200.0, width=3.2)
    assert short.length == pytest.approx(200.0, abs=0.5)
    assert 2 * abs(short.project(*short.cones_xy[5]).lateral) == pytest.approx(3.2, abs=0.02)


def test_random_track_spec_with_a_start_line_of_big_orange_pairs():
    # the start line as FS events and EUFS layouts such as peanut set it: two big orange cones per side,
    # close together; everything else is the same track as "random:SEED"
    plain = load_track("random:4")
    pairs = load_track("random:4,start_pair=0.3")
    assert pairs.source == "generated:random(seed=4, start_pair=0.3)"
    assert pairs.centerline.tobytes() == plain.centerline.tobytes()
    big = pairs.cones_xy[pairs.cone_classes == BIG]
    assert len(big) == 4 and (plain.cone_classes == BIG).sum() == 2
    p = pairs.project(big[:, 0], big[:, 1])
    for sign in (1, -1):
        side = big[np.sign(p.lateral) == sign]
        assert np.linalg.norm(side[0] - side[1]) == pytest.approx(0.3, abs=1e-9)
    assert np.array_equal(pairs.cones_xy[pairs.cone_classes != BIG], plain.cones_xy[plain.cone_classes != BIG])
    assert load_track("random:4, width=3.5 ,spacing=4").source == "generated:random(seed=4, width=3.5, spacing=4)"


def test_csv_round_trip_and_user_track(tmp_path):
    t = generate_random_track(5)
    path = t.to_csv(tmp_path / "mine.csv")
    with pytest.raises(FileExistsError, match="mine.csv"):
        t.to_csv(path)
    xy, cls, start = read_cone_csv(path)
    assert xy.tobytes() == t.cones_xy.tobytes() and cls.tobytes() == t.cone_classes.tobytes()
    assert start == t.start_pose
    u = load_track(path)
    assert u.event == "trackdrive" and u.name == "mine" and u.source == str(path)
    assert u.length == pytest.approx(t.length, rel=0.02)
    assert np.abs(t.project(u.centerline[:, 0], u.centerline[:, 1]).lateral).max() < 0.4
    assert load_track(str(path)).length == pytest.approx(u.length)


def test_three_column_file_without_start(tmp_path):
    t = load_track("oval")
    rows = ["tag,x,y"] + [f"{CONE_CLASSES[c]},{x},{y}" for (x, y), c in zip(t.cones_xy, t.cone_classes, strict=True)]
    (tmp_path / "o.csv").write_text("\n".join(rows) + "\n")
    u = load_track(tmp_path / "o.csv")
    assert u.closed and u.length == pytest.approx(t.length, rel=0.03)
    assert u.point_at(0.0)[:2] == pytest.approx((0.0, -15.0), abs=0.3)  # s = 0 at the big orange cones
    assert u.project(*u.start_pose[:2]).s == pytest.approx(u.length - 6.0, abs=0.3)


BAD_FILES = {
    "unknown tag": ("tag,x,y\nblue,0,1.5\nred,5,1.5\n", 3, "unknown cone colour tag 'red'"),
    "nan": ("tag,x,y\nblue,0,1.5\nyellow,nan,-1.5\n", 3, "positions must be finite"),
    "inf": ("tag,x,y,direction\nblue,0,1.5,0\nyellow,1,-inf,0\n", 3, "positions must be finite"),
    "not a number": ("tag,x,y\nblue,zero,1.5\n", 2, "'zero' is not a number"),
    "short row": ("tag,x,y\nblue,0\n", 2, "at least 3 comma-separated fields"),
    "duplicate": ("# my track\n\ntag,x,y\nblue,0,1.5\nyellow,0,-1.5\nblue,0.004,1.503\n", 6,
                  "duplicates the cone in line 4"),
    "missing header": ("blue,0,1.5\nyellow,0,-1.5\n", 1, "missing header"),
    "two starts": ("tag,x,y,direction\ncar_start,0,0,0\nblue,0,1.5,0\ncar_start,1,0,0\n", 4, "second car_start"),
    "no yellow": ("tag,x,y\nblue,0,1.5\nblue,4,1.5\norange,0,-1.5\n", None, "no yellow cones"),
    "no blue": ("tag,x,y\nyellow,0,1.5\n", None, "no blue cones"),
    "empty": ("", None, "empty file"),
    "header only": ("tag,x,y\n", None, "no cones"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_csv_names_file_and_line(tmp_path, case):
    text, line, message = BAD_FILES[case]
    path = tmp_path / "bad.csv"
    path.write_text(text)
    expected = f"{path}: line {line}: " if line else f"{path}: "
    with pytest.raises(ValueError) as err:
        load_track(path)
    assert str(err.value).startswith(expected) and message in str(err.value)


def test_load_track_spec_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown track 'nope'; valid names: acceleration, b_shape"):
        load_track("nope")
    with pytest.raises(ValueError, match="needs a seed"):
        load_track("random")
    with pytest.raises(ValueError, match="integer seed"):
        load_track("random:x")
    with pytest.raises(FileNotFoundError, match="missing.csv"):
        load_track(str(tmp_path / "missing.csv"))
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        generate_random_track(-1)
    with pytest.raises(ValueError, match="length must be in"):
        generate_random_track(1, length=20.0)
    with pytest.raises(ValueError, match="not 'skidpad'"):
        load_track("peanut", event="skidpad")
    t = load_track("peanut")
    assert load_track(t) is t and load_track("peanut") is t  # shipped tracks are cached (immutable)


@pytest.mark.parametrize("name", [*SHIPPED_TRACKDRIVE, "oval", "random:7"])
def test_reverse_drives_the_same_loop_the_other_way(name):
    t, r = load_track(name), load_track(f"reverse:{name}")
    assert r.name == f"reverse:{t.name}" and r.source == f"reversed:{t.source}" and r.event == "trackdrive"
    assert r.cones_xy.tobytes() == t.cones_xy.tobytes()
    swapped = t.cone_classes.copy()
    swapped[t.cone_classes == BLUE], swapped[t.cone_classes == YELLOW] = YELLOW, BLUE
    assert r.cone_classes.tobytes() == swapped.tobytes()
    assert r.length == pytest.approx(t.length, rel=0.01)
    # the same start line; the centerline runs the other way; the start pose as far before the line
    assert r.point_at(0.0)[:2] == pytest.approx(t.point_at(0.0)[:2], abs=0.3)
    s = np.linspace(0.0, t.length, 40, endpoint=False)
    _, _, h = t.point_at(s)
    hr = r.project(*t.point_at(s)[:2]).heading
    assert np.cos(hr - h).max() < -0.9
    before = t.length - t.project(*t.start_pose[:2]).s
    assert r.length - r.project(*r.start_pose[:2]).s == pytest.approx(before, abs=0.3)
    twice = tr.reverse_track(r)
    assert twice.cone_classes.tobytes() == t.cone_classes.tobytes()
    assert t.project(*twice.start_pose[:2]).s == pytest.approx(t.project(*t.start_pose[:2]).s, abs=0.3)


@pytest.mark.parametrize("name", [*SHIPPED_TRACKDRIVE, "oval", "random:7"])
def test_mirror_reflects_the_loop_and_keeps_blue_on_the_left(name):
    t, m = load_track(name), load_track(f"mirror:{name}")
    assert m.name == f"mirror:{t.name}" and m.source == f"mirrored:{t.source}" and m.event == "trackdrive"
    assert m.cones_xy.tobytes() == (t.cones_xy * [1.0, -1.0]).tobytes()
    assert ((m.cone_classes == BLUE) == (t.cone_classes == YELLOW)).all()
    assert m.length == pytest.approx(t.length, rel=0.01)
    assert m.start_pose == pytest.approx((t.start_pose[0], -t.start_pose[1], -t.start_pose[2]), abs=1e-9)
    assert m.curvature.sum() == pytest.approx(-t.curvature.sum(), rel=0.05)  # every left turn a right one
    assert tr.mirror_track(m).cones_xy.tobytes() == t.cones_xy.tobytes()


def test_reverse_spec_errors():
    for open_track in ("acceleration", "skidpad"):
        with pytest.raises(ValueError, match=f"'{open_track}' is an open .* only a closed loop"):
            load_track(f"reverse:{open_track}")
        with pytest.raises(ValueError, match=f"'{open_track}' is an open .* only a closed loop can be mirrored"):
            load_track(f"mirror:{open_track}")
    with pytest.raises(ValueError, match="needs a track spec after it"):
        load_track("reverse:")
    with pytest.raises(ValueError, match="unknown track 'nope'"):
        load_track("reverse:nope")
    with pytest.raises(ValueError, match="not 'skidpad'"):
        load_track("reverse:peanut", event="skidpad")
    assert not tr.is_track_file("reverse:my/track.csv") and not tr.is_track_file("mirror:my/track.csv")
    assert tr.track_file_part("mirror:reverse:my/track.csv") == ("mirror:reverse:", "my/track.csv")
    assert load_track("mirror:reverse:peanut").name == "mirror:reverse:peanut"
    assert load_track("reverse:random", seed=3).source == "reversed:generated:random(seed=3)"


def test_car_start_against_the_driving_direction(tmp_path):
    src = tr.data_dir("tracks") / "eufs" / "small_track.csv"
    text = src.read_text().replace("car_start,0.0,0.0,0,", "car_start,0.0,0.0,3.1416,")
    (tmp_path / "backwards.csv").write_text(text)
    with pytest.raises(ValueError, match="backwards.csv: car_start faces against the driving direction"):
        load_track(tmp_path / "backwards.csv")


def test_track_validates_its_fields():
    t = load_track("oval")
    with pytest.raises(ValueError, match="unknown event"):
        Track(**{**_fields(t), "event": "autocross"})
    with pytest.raises(ValueError, match="half widths"):
        Track(**{**_fields(t), "half_width_left": t.half_width_left[:-1]})


def _fields(t: Track) -> dict:
    names = ("name", "cones_xy", "cone_classes", "centerline", "closed", "event", "start_pose", "half_width_left",
             "half_width_right", "finish_s", "source", "start_line_s")
    return {n: getattr(t, n) for n in names}


def test_cli_list_show_export(tmp_path, capsys):
    from weather_gym.cli import main

    assert main(["tracks", "list"]) == 0
    out = capsys.readouterr().out
    for name in [*tr.SHIPPED, "oval", "random:7"]:
        assert name in out
    png = tmp_path / "peanut.png"
    assert main(["tracks", "show", "peanut", "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["tracks", "show", "peanut", "--out", str(png)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    csv = tmp_path / "r.csv"
    assert main(["tracks", "export", "random:3", "--out", str(csv)]) == 0
    assert read_cone_csv(csv)[0].tobytes() == generate_random_track(3).cones_xy.tobytes()


def test_track_pickles_for_worker_processes():
    import pickle

    t = load_track("skidpad")
    u = pickle.loads(pickle.dumps(t))
    assert u.centerline.tobytes() == t.centerline.tobytes() and u.finish_s == t.finish_s
    assert u.project(18.5, 0.0, s_hint=50.0).s == pytest.approx(t.project(18.5, 0.0, s_hint=50.0).s)


@pytest.mark.parametrize("name", ["peanut", "skidpad", "acceleration"])
def test_one_point_projection_gives_the_floats_of_the_array_path(name):
    # project(x, y) on plain floats takes a faster path (every env step); it must not change a result
    t = load_track(name)
    rng = np.random.default_rng(5)
    s = rng.uniform(-5.0, t.length + 5.0, 60)
    x, y, _ = t.point_at(np.clip(s, 0.0, t.length))
    x, y = x + rng.normal(0, 1.5, 60), y + rng.normal(0, 1.5, 60)
    for k in range(60):
        for hint in (None, float(s[k])):
            one = t.project(float(x[k]), float(y[k]), s_hint=hint)
            arr = t.project(np.array([x[k]]), np.array([y[k]]), s_hint=hint)
            assert (one.s, one.lateral, one.heading, one.index) == (arr.s[0], arr.lateral[0], arr.heading[0], arr.index[0])


def test_a_csv_track_is_shown_by_its_name_not_this_machines_path(tmp_path, monkeypatch):
    from weather_gym.core.paths import data_dir
    from weather_gym.tracks import source_label, track_label

    csv = tmp_path / "deep" / "test_day.csv"
    csv.parent.mkdir()
    csv.write_text((data_dir("tracks") / "eufs" / "peanut.csv").read_text())
    assert track_label(str(csv)) == "test_day" and track_label(f"mirror:{csv}") == "mirror:test_day"
    assert track_label("random:7") == "random:7" and track_label("hairpin") == "hairpin"
    monkeypatch.chdir(tmp_path)  # far from the checkout: shipped files still show as tracks/...
    assert source_label(load_track("peanut").source) == "tracks/eufs/peanut.csv"
    assert source_label(str(csv)) == "test_day.csv"
    assert source_label(load_track("oval").source).startswith("generated:oval(")


def test_a_track_list_keeps_a_random_tracks_arguments_with_it():
    from weather_gym.tracks import split_track_specs

    specs = split_track_specs("peanut,random:1,width=2.5,reverse:random:2,width=2.8,length=200, mirror:hairpin")
    assert specs == ("peanut", "random:1,width=2.5", "reverse:random:2,width=2.8,length=200", "mirror:hairpin")
    narrow = load_track(specs[1])
    assert min(narrow.half_width_left.min(), narrow.half_width_right.min()) < 1.3  # 2.5 m wide
    assert split_track_specs(" , ") == ()
