"""Presets resolved per scenario: the search, the typed errors, the cache and the switch between meanings."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from weather_gym.core.errors import InputError, ResolutionError
from weather_gym.lab.calibration import resolve as rs
from weather_gym.lab.calibration.frame_ap import FrameMatches
from weather_gym.lab.calibration.resolve import (
    Resolution,
    ResolvedRow,
    Scenario,
    resolution_key,
    resolve_presets,
)
from weather_gym.weather import (
    load_presets,
    parse_weather,
    preset_source,
    preset_spec,
    to_spec,
    weather_source,
)
from weather_gym.weather.presets import DEFAULT_PRESETS


def _clear() -> FrameMatches:
    one = [[np.array([0.9]) for _ in range(4)]]
    return FrameMatches(("blue",), one, [[np.array([1.0]) for _ in range(4)]], np.ones((1, 4)), 4)


class _Curve(rs._Search):
    """The search on a known curve: relative mAP = f(k), no frames."""

    def __init__(self, f, items, curve=None):
        super().__init__(None, items, _clear(), 1.0, Scenario(tracks=("demo",)), lambda: None, curve)
        self.f = f

    def measure(self, k):
        self.points[k] = float(self.f(k))
        self.matches[k] = _clear()


def _items(cond="low_light"):
    table = load_presets()["presets"][cond]
    return [(s, table[s]) for s in (1, 2, 3, 4)]


@pytest.mark.parametrize("shift", [-0.03, 0.0, 0.025])
def test_search_finds_the_k_of_a_shifted_curve(shift):
    """A scenario whose curve is the pool's moved along k: every row lands on its target, in few steps."""
    items = _items()
    ks, rel = rs._pool_curve([(t["effects"][0]["k"], t["measured_relative"]) for _, t in items])

    def f(k):
        return float(np.interp(k - shift, ks, rel, left=1.0, right=rel[-1] * 0.5))

    search = _Curve(f, items)
    for sev, t in items:
        row = search.row("low_light", sev, t)
        assert abs(row.achieved - row.target) <= rs.HIT
        # k is known as well as HIT allows: where the true curve is within HIT of the target
        assert abs(f(row.k) - row.target) <= rs.HIT
        if abs(f(float(t["effects"][0]["k"])) - row.target) > rs.HIT:  # the pool k misses: k moved with the curve
            assert row.k == pytest.approx(float(t["effects"][0]["k"]) + shift, abs=0.01)
        assert row.evals <= 4
        assert row.reachable and row.effect["mode"] == "night"


@pytest.mark.parametrize(("k50", "steep"), [(0.80, 25.0), (0.80, 40.0), (0.82, 25.0), (0.82, 40.0)])
def test_secant_steps_in_logit_land_an_s_curve_in_few_evaluations(k50, steep):
    """A relative mAP that falls in an S (as low light's does), unlike the pool curve's straight pieces: the
    four rows land within HIT in at most 10 k values together (the points of one row serve the next)."""
    items = _items()

    def f(k):
        return float(1.0 / (1.0 + np.exp(steep * (k - k50))))

    search = _Curve(f, items)
    rows = [search.row("low_light", sev, t) for sev, t in items]
    for row in rows:
        assert abs(row.achieved - row.target) <= rs.HIT
        assert abs(f(row.k) - row.target) <= rs.HIT
    assert sum(r.evals for r in rows) <= 10
    assert len(search.points) == sum(r.evals for r in rows)


def _plateau(k):
    """A detector's low-light curve with a plateau (the second detector's on the skidpad, calibration.md):
    steep to 0.13, flat at 0.13-0.11 from k 0.62 to 0.72, steep again."""
    ks = [0.0, 0.45, 0.499, 0.551, 0.619, 0.72, 0.736, 0.774, 0.85, 1.0]
    rel = [1.0, 0.85, 0.62, 0.35, 0.13, 0.11, 0.086, 0.032, 0.013, 0.0]
    return float(np.interp(k, ks, rel))


def test_a_plateau_does_not_stop_the_search():
    """Regula falsi creeps from one end of a bracket where the curve bends (in logit); the search bisects when
    the same end moved twice, so every row lands within HIT before MAX_EVALS."""
    items = _items()
    search = _Curve(_plateau, items)
    for sev, t in items:
        row = search.row("low_light", sev, t)
        assert abs(row.achieved - row.target) <= rs.HIT, (sev, row.note, sorted(search.points.items()))
        assert not row.note


@pytest.mark.parametrize("shift", [0.0, 0.015, -0.02])
def test_a_smaller_sets_curve_sizes_the_first_step(shift):
    """After a widening, the rows step along the smaller set's measured curve, not the pool presets': on a curve
    moved a little from the smaller set's, the four rows land in fewer k's together (at most 6)."""
    items = _items()

    def f_small(k):
        return float(1.0 / (1.0 + np.exp(30.0 * (k - 0.60))))

    def f_big(k):
        return f_small(k - shift)

    small = _Curve(f_small, items)
    starts = {sev: small.row("low_light", sev, t).k for sev, t in items}
    curve = [[k, v] for k, v in sorted(small.points.items())]
    evals = {}
    for name, c in (("smaller set's curve", curve), ("pool curve", None)):
        big = _Curve(f_big, items, c)
        rows = [big.row("low_light", sev, t, starts[sev]) for sev, t in items]
        assert all(abs(r.achieved - r.target) <= rs.HIT for r in rows)
        evals[name] = sum(r.evals for r in rows)
    assert evals["smaller set's curve"] <= 6
    assert evals["smaller set's curve"] < evals["pool curve"]


def test_logit_secant_and_pool_k():
    assert rs._secant(0.5, 0.5, 0.6, 0.5, 0.3) is None  # flat: no step
    # on a logistic curve the logit secant is exact
    k = rs._secant(0.7, 1 / (1 + np.exp(3.0)), 0.8, 1 / (1 + np.exp(4.0)), 1 / (1 + np.exp(6.0)))
    assert k == pytest.approx(1.0)
    ks, rel = np.array([0.0, 0.5, 0.8]), np.array([1.0, 0.5, 0.1])
    assert rs._pool_k(ks, rel, 0.5) == pytest.approx(0.5)
    assert 0.5 < rs._pool_k(ks, rel, 0.3) < 0.8 and rs._pool_k(ks, rel, 0.05) > 0.8 and rs._pool_k(ks, rel, 1.0) == 0.0


def test_target_out_of_reach_is_a_typed_error():
    items = _items()
    search = _Curve(lambda k: 1.0 - 0.3 * k, items)  # never below 0.7
    with pytest.raises(ResolutionError, match=r"low_light@2 .*out of the effect's reach.*k = 1.*0\.700"):
        search.row("low_light", 2, items[1][1])


def test_a_rise_is_k0_and_said_so():
    items = [(s, t) for s, t in _items("droplets")]
    search = _Curve(lambda k: 1.0 - 0.4 * k, items)
    row = search.row("droplets", 1, items[0][1])  # target 1.004: above the clear level
    assert row.k == 0.0 and not row.reachable and "only lowers it" in row.note


def test_scenario_is_checked_and_described():
    assert Scenario(tracks="skidpad").tracks == ("skidpad",)
    assert "shipped detector" in Scenario().describe()
    with pytest.raises(InputError, match="max_frames"):
        Scenario(frames=100, max_frames=50)
    with pytest.raises(InputError, match="frames must be an integer"):
        Scenario(frames=0)


def test_key_changes_with_what_changes_the_result():
    a = resolution_key(Scenario(tracks=("skidpad",)))
    assert a == resolution_key(Scenario(tracks=("skidpad",)))
    assert a != resolution_key(Scenario(tracks=("hairpin",)))
    assert a != resolution_key(Scenario(tracks=("skidpad",), scene="realistic"))
    assert a != resolution_key(Scenario(tracks=("skidpad",)), tolerance=0.03)


def test_cache_dir_from_env(monkeypatch, tmp_path):
    monkeypatch.setenv(rs.CACHE_ENV, str(tmp_path / "c"))
    assert rs.cache_dir() == tmp_path / "c"
    monkeypatch.setenv(rs.CACHE_ENV, "off")
    assert rs.cache_dir() is None
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            monkeypatch.setenv(rs.CACHE_ENV, str(ro / "c"))
            assert rs.cache_dir() is None  # a read-only place: no cache, resolved every time
        finally:
            ro.chmod(0o700)


def test_cached_use_reads_the_entry_without_computing(monkeypatch, tmp_path):
    monkeypatch.setenv(rs.CACHE_ENV, str(tmp_path))
    sc = Scenario(tracks=("skidpad",))
    key = resolution_key(sc)
    row = ResolvedRow("low_light", 2, 0.344, 0.85, 0.843, 0.345, 0.01, (0.33, 0.36), (0.849, 0.851), True,
                      {"name": "dim", "k": 0.85, "mode": "night"}, 3)
    res = Resolution(sc.describe(), key, [row], 0.95, 900, 160, 12.0, None)
    res.path = rs.write_resolved(res, tmp_path / "resolved" / f"{key}.toml")
    (tmp_path / "resolved" / f"{key}.json").write_text(json.dumps(res.to_dict()))
    monkeypatch.setattr(rs, "_compute", lambda *a, **k: pytest.fail("computed instead of read"))
    got = resolve_presets(sc, progress=False)
    assert got.cached and got.row("low_light", 2).k == 0.85
    assert preset_spec("low_light", 2, got.path)[0]["k"] == 0.85
    assert preset_source(got.path) == "resolved"


def test_a_damaged_entry_is_computed_again(monkeypatch, tmp_path):
    monkeypatch.setenv(rs.CACHE_ENV, str(tmp_path))
    sc = Scenario(tracks=("skidpad",))
    (tmp_path / "resolved").mkdir()
    (tmp_path / "resolved" / f"{resolution_key(sc)}.json").write_text("{not json")
    calls = []
    monkeypatch.setattr(rs, "_compute", lambda *a, **k: calls.append(1) or (_ for _ in ()).throw(RuntimeError("x")))
    with pytest.raises(RuntimeError):
        resolve_presets(sc, progress=False)
    assert calls


def test_presets_switch_and_sources(monkeypatch, tmp_path):
    sc = Scenario(tracks=("skidpad",))
    row = ResolvedRow("low_light", 2, 0.344, 0.86, 0.843, 0.345, 0.01, (0.33, 0.36), (0.859, 0.861), True,
                      {"name": "dim", "k": 0.86, "mode": "night"}, 3)
    path = rs.write_resolved(Resolution(sc.describe(), "k", [row], 0.95, 900, 160, 1.0, None), tmp_path / "r.toml")
    assert weather_source("low_light@2") == "pool" and weather_source("dim:0.5") == "given"
    assert weather_source("low_light@2", path) == "resolved"
    assert to_spec(parse_weather("low_light@2", path))[0]["k"] == 0.86
    assert to_spec(parse_weather("dim:0.5:mode=night", path))[0]["k"] == 0.5  # explicit k never changes
    monkeypatch.setenv("WEATHER_GYM_PRESETS", str(path))
    assert preset_spec("low_light", 2)[0]["k"] == 0.86 and weather_source("low_light@2") == "resolved"
    assert preset_spec("droplets", 3) == load_presets(DEFAULT_PRESETS)["presets"]["droplets"][3]["effects"]
    monkeypatch.setenv("WEATHER_GYM_PRESETS", "pool")
    assert preset_spec("low_light", 2)[0]["k"] == 0.87
    monkeypatch.setenv("WEATHER_GYM_PRESETS", str(tmp_path / "missing.toml"))
    with pytest.raises(FileNotFoundError, match="WEATHER_GYM_PRESETS"):
        preset_spec("low_light", 2)


def test_wrapper_records_k_source(tmp_path):
    import gymnasium as gym

    from weather_gym.wrappers import WeatherWrapper

    class Camera(gym.Env):
        observation_space = gym.spaces.Box(0, 255, (16, 16, 3), np.uint8)
        action_space = gym.spaces.Discrete(1)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            return np.full((16, 16, 3), 120, np.uint8), {}

        def step(self, action):
            return np.full((16, 16, 3), 120, np.uint8), 0.0, False, False, {}

    row = ResolvedRow("droplets", 4, 0.74, 0.7, 0.673, 0.74, 0.01, (0.72, 0.76), (0.69, 0.71), True,
                      {"name": "droplets", "k": 0.7, "mode": "refractive"}, 2)
    path = rs.write_resolved(Resolution("s", "k", [row], 0.95, 900, 160, 1.0, None), tmp_path / "r.toml")
    env = WeatherWrapper(Camera(), weather="droplets@4", presets=str(path))
    _, info = env.reset(seed=0)
    assert info["weather_source"] == "resolved" and info["weather"][0]["k"] == 0.7
    _, info = env.reset(seed=0, options={"weather": "droplets:0.3"})
    assert info["weather_source"] == "given"
    env.set_weather("droplets@4")
    assert env.step(0)[4]["weather_source"] == "resolved"
    assert WeatherWrapper(Camera(), weather="droplets@4").reset(seed=0)[1]["weather_source"] == "pool"


def _few_cones_set(tmp_path: Path, src: Path) -> Path:
    from tests.lab.calibration.conftest import subset_coco

    return subset_coco(src, tmp_path / "two", 2)


def test_too_few_cones_is_a_typed_error(calib_set_8, tmp_path, monkeypatch):
    monkeypatch.setenv(rs.CACHE_ENV, "off")
    two = _few_cones_set(tmp_path, calib_set_8)
    with pytest.raises(ResolutionError, match=r"recording .*two.*only \d+ blue and yellow cones.*at least 100"):
        resolve_presets(Scenario(dataset=str(two)), progress=False)


def test_evaluate_cells_take_presets_per_track_and_record_their_source(tmp_path):
    from weather_gym.lab.evaluation.evaluate import CELL_KEY_FIELDS, EvalConfig, make_cells

    row = ResolvedRow("low_light", 2, 0.344, 0.86, 0.843, 0.345, 0.01, (0.33, 0.36), (0.859, 0.861), True,
                      {"name": "dim", "k": 0.86, "mode": "night"}, 3)
    path = rs.write_resolved(Resolution("s", "k", [row], 0.95, 900, 160, 1.0, None), tmp_path / "r.toml")
    cfg = EvalConfig(effects=("low_light",), severities=(0, 2), seeds=(0,), tracks=("small_track", "peanut"),
                     presets={"small_track": str(path), "peanut": str(DEFAULT_PRESETS)})
    cells = {(c.track, c.severity): c for c in make_cells(cfg)}
    assert json.loads(cells["small_track", 2].weather)[0]["k"] == 0.86
    assert json.loads(cells["peanut", 2].weather)[0]["k"] == 0.87
    assert (cells["small_track", 2].k_source, cells["peanut", 2].k_source, cells["peanut", 0].k_source) == \
        ("resolved", "pool", "given")
    assert "k_source" not in CELL_KEY_FIELDS  # the k itself is in `weather`: old results.csv files still resume
    with pytest.raises(InputError, match="no presets file for track 'hairpin'"):
        make_cells(EvalConfig(effects=("low_light",), severities=(2,), seeds=(0,), tracks=("hairpin",),
                              presets={"small_track": str(path)}))


def _resolve_in_child(cache: str, marker_dir: str, q) -> None:
    import os as _os
    import time as _time

    _os.environ[rs.CACHE_ENV] = cache

    def fake_compute(scenario, presets, tolerance, key, frames_root, out, progress, threads, workers=1):
        (Path(marker_dir) / f"computed-{_os.getpid()}").write_text("x")
        _time.sleep(1.5)  # long enough for the other process to arrive and wait
        row = ResolvedRow("low_light", 2, 0.344, 0.85, 0.843, 0.345, 0.01, (0.33, 0.36), (0.849, 0.851), True,
                          {"name": "dim", "k": 0.85, "mode": "night"}, 3)
        res = Resolution(scenario.describe(), key, [row], 0.95, 900, 160, 1.5, None)
        res.path = rs.write_resolved(res, out, overwrite=True)
        return res

    rs._compute = fake_compute
    res = resolve_presets(Scenario(tracks=("skidpad",)), progress=False)
    q.put((res.cached, res.row("low_light", 2).k))


def test_concurrent_processes_compute_once(tmp_path):
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    q = ctx.Queue()
    procs = [ctx.Process(target=_resolve_in_child, args=(str(tmp_path / "cache"), str(tmp_path), q)) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    results = sorted(q.get(timeout=5) for _ in procs)
    assert len(list(tmp_path.glob("computed-*"))) == 1  # one computed, the other waited and read its result
    assert results == [(False, 0.85), (True, 0.85)]


def test_code_version_is_remembered_by_file_stats(monkeypatch, tmp_path):
    """A new process stats the source files and reads their content hash from the cache folder."""
    monkeypatch.setenv(rs.CACHE_ENV, "off")
    rs.code_version.cache_clear()
    fresh = rs.code_version()
    monkeypatch.setenv(rs.CACHE_ENV, str(tmp_path))
    rs.code_version.cache_clear()
    assert rs.code_version() == fresh  # computed and remembered
    (memo,) = (tmp_path / "code").glob("*.txt")
    memo.write_text("0123456789abcdef\n")  # the remembered value is what a new process reads
    rs.code_version.cache_clear()
    assert rs.code_version() == "0123456789abcdef"
    rs.code_version.cache_clear()


def test_helper_processes_give_the_same_detections(calib_set_8, tmp_path):
    """A helper process degrades and detects its share of the frames; the result is the one-process one."""
    sc = Scenario(dataset=str(calib_set_8))
    table = {"name": "dim", "k": 0.8, "mode": "night"}
    one = rs._ReferenceSet(sc, tmp_path, rs.load_detector(None), progress=False, workers=1)
    two = rs._ReferenceSet(sc, tmp_path, rs.load_detector(None), progress=False, workers=2)
    try:
        for ref in (one, two):
            ref.widen()
        assert len(two.helpers) == 1 and two.chunks[0]["cuts"].tolist() == [0, 4, 8]
        for label, t, k in (("clear", None, 0.0), ("dim", table, 0.8)):
            a, b = one.matches(label, t, k), two.matches(label, t, k)
            assert a.map50() == b.map50()
            for c in range(len(a.classes)):
                for g in range(a.n_groups):
                    np.testing.assert_array_equal(a.scores[c][g], b.scores[c][g])
        assert one.matches("dim", table, 0.8).map50() < one.matches("clear", None, 0.0).map50()
    finally:
        two.close()
    assert two.helpers == []
