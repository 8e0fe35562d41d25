"""Validation of the surrogate against the full pipeline on a track not used for fitting.

For every condition and severity, ``mapper_pure_pursuit`` drives one lap per seed through the full
pipeline (render -> weather -> detector) and through the surrogate, both logged the same way
(:func:`weather_gym.lab.training.surrogate.record.record`). From the logs, the cone-list statistics
(:func:`cone_stats`): recall per range bin, false positives per frame, range-error spread (IQR),
wrong-class rate, mean run length of misses; from the episodes, the lap metrics (completion, lap
time, cones hit, mean cross-track error).

Checks. A surrogate statistic (pooled over its seeds) passes when it lies in the full pipeline's
95 % interval: the union of (a) the prediction interval of one seed's value across the full
pipeline's seeds (mean +- t(0.975, n-1) sd sqrt(1 + 1/n)) and (b) the 2.5-97.5 % range of a block
bootstrap (blocks of :data:`BLOCK` frames of the full-pipeline episodes, :data:`BOOT` resamples):
(b) matters where the full pipeline gives the same numbers for every seed (clear weather and low
light have no random part; the driver is deterministic). A lap metric passes when the surrogate's
seed mean is within 2 pooled standard deviations (across seeds) of the full pipeline's.

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.training.surrogate.validate import miss_runs
    >>> miss_runs(np.zeros(6, int), np.array([3, 3, 3, 3, 5, 5]), np.array([0, 1, 2, 3, 0, 1]),
    ...           np.array([0, 0, 1, 0, 0, 0], bool)).tolist()
    [2, 1, 2]
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from scipy.stats import t

from weather_gym.core._figures import save_figure
from weather_gym.core._io import atomic_write, check_output
from weather_gym.core.errors import InputError
from weather_gym.lab.training.surrogate.record import record
from weather_gym.perception.labels import MIN_BOX_HEIGHT_PX, SmallRule
from weather_gym.perception.scoring import DEFAULT_RANGE_BINS
from weather_gym.surrogate.camera import fitted_input_size
from weather_gym.surrogate.conditions import SurrogateFallbackWarning, fallback_note, split_nominal
from weather_gym.surrogate.log import SurrogateLog, load_log, save_log
from weather_gym.surrogate.model import SHIPPED_MODEL, load_model
from weather_gym.weather.presets import canonical_condition

__all__ = ["cone_stats", "miss_runs", "min_box_height", "validate", "STAT_NAMES", "LAP_METRICS"]

BLOCK = 50
BOOT = 300
MIN_CONES = 30
"""A recall bin with fewer cones (of one episode, or pooled) is not scored (n/a)."""
RATES = ("recall", "wrong class rate")
LAP_METRICS = ("completed", "lap_time_s", "cones_hit", "cte_mean_m")


def _bin_label(lo: float, hi: float) -> str:
    return f"{lo:g}+ m" if math.isinf(hi) else f"{lo:g}-{hi:g} m"


BIN_LABELS = [_bin_label(lo, hi) for lo, hi in zip(DEFAULT_RANGE_BINS[:-1], DEFAULT_RANGE_BINS[1:], strict=True)]
STAT_NAMES = (*(f"recall {b}" for b in BIN_LABELS), "FP per frame", "range error IQR (m)", "wrong class rate",
              "miss run length (frames)")


def miss_runs(episode: np.ndarray, cone_id: np.ndarray, frame: np.ndarray, detected: np.ndarray) -> np.ndarray:
    """Lengths of the runs of consecutive frames in which a visible cone was missed."""
    if not len(frame):
        return np.zeros(0, np.int64)
    order = np.lexsort((frame, cone_id, episode))
    e, c, f, d = episode[order], cone_id[order], frame[order], detected[order]
    miss = ~d
    cont = np.r_[False, (e[1:] == e[:-1]) & (c[1:] == c[:-1]) & (f[1:] == f[:-1] + 1) & miss[1:] & miss[:-1]]
    starts = miss & ~cont
    run_id = np.cumsum(starts) - 1
    return np.bincount(run_id[miss], minlength=int(starts.sum())).astype(np.int64)


def min_box_height(log: SurrogateLog) -> float:
    """The scored box height (camera pixels) of the log's camera: the too-small rule at the detector's input
    (``SmallRule``; 8 px at 672x376, where the detector's input is 512x288)."""
    inp = fitted_input_size(log.meta)  # the recorded detector input, else the shipped detector's
    if inp is None:  # no camera named
        return MIN_BOX_HEIGHT_PX
    cam = log.meta["camera"]
    return SmallRule((int(cam["width"]), int(cam["height"])), inp).min_height_px


def _pieces(log: SurrogateLog) -> dict[str, np.ndarray]:
    """Per-row inputs of the statistics, cones of at least the scored box height."""
    c = log.cones
    keep = c["box_h"] >= min_box_height(log)
    return {k: (v[keep] if k != "box" else v[keep]) for k, v in c.items()}


def cone_stats(log: SurrogateLog, cones: dict[str, np.ndarray] | None = None,
               frames: dict[str, np.ndarray] | None = None) -> dict[str, float]:
    """The cone-list statistics (:data:`STAT_NAMES`) of a log (or of given rows of it).

    Cones shorter than the scored box height (:func:`min_box_height`) are left out, as the scoring does.
    """
    c = cones if cones is not None else _pieces(log)
    fr = frames if frames is not None else log.frames
    out: dict[str, float] = {}
    det = c["detected"].astype(bool)
    edges = np.asarray(DEFAULT_RANGE_BINS)
    b = np.clip(np.searchsorted(edges, c["range"], side="right") - 1, 0, len(edges) - 2)
    for i, label in enumerate(BIN_LABELS):
        sel = b == i
        out[f"recall {label}"] = float(det[sel].mean()) if sel.sum() >= MIN_CONES else math.nan
    out["FP per frame"] = float(fr["n_fp"].sum() / max(len(fr["n_fp"]), 1))
    err = c["range_err"][det]
    err = err[np.isfinite(err)]
    out["range error IQR (m)"] = float(np.subtract(*np.quantile(err, [0.75, 0.25]))) if len(err) else math.nan
    out["wrong class rate"] = float(np.mean(c["det_cls"][det] != c["cls"][det])) if det.any() else math.nan
    runs = miss_runs(c["episode"], c["cone_id"], c["frame"], det)
    out["miss run length (frames)"] = float(runs.mean()) if len(runs) else math.nan
    return out


def _per_episode(log: SurrogateLog) -> list[dict[str, float]]:
    c = _pieces(log)
    out = []
    for e in range(len(log.episodes)):
        cs = {k: v[c["episode"] == e] for k, v in c.items()}
        fs = {k: v[log.frames["episode"] == e] for k, v in log.frames.items()}
        out.append(cone_stats(log, cs, fs))
    return out


def _bootstrap(log: SurrogateLog, rng: np.random.Generator) -> dict[str, tuple[float, float]]:
    c = _pieces(log)
    fr = log.frames
    cb = c["episode"].astype(np.int64) * 100000 + c["frame"] // BLOCK
    fb = fr["episode"].astype(np.int64) * 100000 + fr["frame"] // BLOCK
    blocks = np.unique(fb)
    c_idx = {blk: np.flatnonzero(cb == blk) for blk in blocks}
    f_idx = {blk: np.flatnonzero(fb == blk) for blk in blocks}
    draws: dict[str, list[float]] = {k: [] for k in STAT_NAMES}
    for _ in range(BOOT):
        pick = rng.choice(blocks, len(blocks), replace=True)
        ci = np.concatenate([c_idx[p] for p in pick])
        fi = np.concatenate([f_idx[p] for p in pick])
        cs = {k: v[ci] for k, v in c.items()}
        # resampled blocks are distinct copies: give each its own episode id so runs do not join up
        copy_id = np.repeat(np.arange(len(pick)), [len(c_idx[p]) for p in pick])
        cs["episode"] = copy_id.astype(np.int64)
        fs = {k: v[fi] for k, v in fr.items()}
        for k, v in cone_stats(log, cs, fs).items():
            draws[k].append(v)
    out = {}
    for k, vs in draws.items():
        a = np.asarray(vs, np.float64)
        a = a[np.isfinite(a)]
        out[k] = (float(np.quantile(a, 0.025)), float(np.quantile(a, 0.975))) if len(a) else (math.nan, math.nan)
    return out


def _seed_interval(values: Sequence[float]) -> tuple[float, float]:
    a = np.asarray([v for v in values if np.isfinite(v)], np.float64)
    if len(a) < 2:
        return (math.nan, math.nan)
    half = float(t.ppf(0.975, len(a) - 1)) * float(a.std(ddof=1)) * math.sqrt(1 + 1 / len(a))
    return float(a.mean() - half), float(a.mean() + half)


def _lap_table(episodes: list[dict[str, Any]]) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {k: [] for k in LAP_METRICS}
    for ep in episodes:
        out["completed"].append(1.0 if ep.get("completed") else 0.0)
        out["lap_time_s"].append(float(ep["lap_time_s"]) if ep.get("lap_time_s") is not None else math.nan)
        out["cones_hit"].append(float(ep.get("cones_hit", math.nan)))
        out["cte_mean_m"].append(float(ep.get("cte_mean_m", math.nan)))
    return out


def _lap_check(full: Sequence[float], sur: Sequence[float]) -> tuple[float, float, float, float, bool | None]:
    f = np.asarray([v for v in full if np.isfinite(v)])
    s = np.asarray([v for v in sur if np.isfinite(v)])
    if not len(f) or not len(s):
        return (math.nan, math.nan, math.nan, math.nan, None)
    sf = float(f.std(ddof=1)) if len(f) > 1 else 0.0
    ss = float(s.std(ddof=1)) if len(s) > 1 else 0.0
    pooled = math.sqrt((sf ** 2 + ss ** 2) / 2)
    ok = abs(float(s.mean()) - float(f.mean())) <= 2 * pooled + 1e-9
    return float(f.mean()), sf, float(s.mean()), ss, ok


def _weathers(conditions: Sequence[str], severities: Sequence[int]) -> list[str]:
    out = []
    if 0 in severities:
        out.append("clear")
    for cond in conditions:
        cond = canonical_condition(cond)
        for s in severities:
            if s != 0:
                out.append(f"{cond}@{s}")
    return out


def _fmt(v: float, nd: int = 3) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v:.{nd}f}"


def validate(*, model: str | os.PathLike | None = None, track: str = "hairpin",
             conditions: Sequence[str] = ("droplets", "low_light"), severities: Sequence[int] = (0, 1, 2, 3, 4),
             seeds: Sequence[int] = (0, 1, 2), surrogate_seeds: Sequence[int] = tuple(range(10)), steps: int = 900,
             full_logs: str | os.PathLike | None = None, out: str | os.PathLike, overwrite: bool = False,
             progress: Callable[[str], None] | None = None, camera: tuple[int, int] | None = None,
             weathers: Sequence[str] | None = None) -> dict[str, Any]:
    """Run the validation and write ``OUT/report.md``, ``OUT/validation.json`` and two PNGs; returns the numbers.

    ``full_logs``: a folder of full-pipeline logs of this track (``clear.npz``, ``droplets_3.npz``...):
    the ones there are reused, the missing ones recorded and saved there (default ``OUT/full_logs``).
    ``camera``: (W, H) of the camera both run at (None: the scenario's, 672x376); a reused log must be of
    that camera. ``weathers``: the weathers to check (e.g. ``["clear", "droplets@3", "rain@2"]``), instead of
    every ``conditions`` x ``severities``; an effect the model has no fit of runs on its fallback (clear).
    """

    for s in severities:
        if not (isinstance(s, int) and 0 <= s <= 4):
            raise InputError(f"severities must be integers 0..4, got {s!r}")
    out = Path(out)
    report = out / "report.md"
    for name in ("report.md", "validation.json", "recall_by_range.png", "fp_and_runs.png"):
        check_output(out / name, overwrite=overwrite, what="validation output")
    model_path = Path(model) if model is not None else SHIPPED_MODEL
    m = load_model(model_path)
    if track in set(m.meta.get("tracks", [])):
        raise InputError(f"track {track!r} was used for fitting the surrogate model ({', '.join(m.meta['tracks'])}); "
                         f"validate on another track")
    logs_dir = Path(full_logs) if full_logs is not None else out / "full_logs"
    say = progress or (lambda line: None)
    rng = np.random.default_rng(0)
    env_kwargs = {} if camera is None else {"camera": {"width": int(camera[0]), "height": int(camera[1])}}
    results: dict[str, Any] = {"track": track, "model": os.path.basename(model_path), "seeds": list(seeds),
                               "surrogate_seeds": list(surrogate_seeds), "steps": steps, "rows": []}
    for weather in (list(weathers) if weathers else _weathers(conditions, severities)):
        f = logs_dir / f"{weather.replace('@', '_')}.npz"
        if f.is_file():
            full = load_log(f)
            if full.episodes and full.episodes[0].get("track") != track:
                raise InputError(f"{f} is a log of track {full.episodes[0].get('track')!r}, not {track!r}")
            cam = full.meta.get("camera") or {}
            if camera is not None and (cam.get("width"), cam.get("height")) != tuple(camera):
                raise InputError(f"{f} is a log of a {cam.get('width')}x{cam.get('height')} camera, not "
                                 f"{camera[0]}x{camera[1]}")
        else:
            say(f"full pipeline: {weather} on {track}, seeds {list(seeds)}")
            full = record(tracks=[track], weathers=[weather], seeds=seeds, steps=steps, agent="mapper_pure_pursuit",
                          env_kwargs=env_kwargs)
            save_log(full, f)
        say(f"surrogate: {weather} on {track}, seeds {list(surrogate_seeds)}")
        with warnings.catch_warnings():  # the report names the fallback (below)
            warnings.simplefilter("ignore", SurrogateFallbackWarning)
            sur = record(tracks=[track], weathers=[weather], seeds=surrogate_seeds, steps=steps,
                         agent="mapper_pure_pursuit", perception="surrogate",
                         perception_kwargs={"model": str(model_path)}, env_kwargs=env_kwargs)
        _, dropped = split_nominal(weather, m.conditions())
        fallback = fallback_note(dropped, with_k=False) if dropped else None
        cam = full.meta.get("camera") or {}
        results.setdefault("camera", f"{cam.get('width')}x{cam.get('height')}")
        results.setdefault("min_box_height_px", min_box_height(full))
        if full.meta.get("detector_input"):
            results.setdefault("detector_input", "x".join(str(v) for v in full.meta["detector_input"]))
        per_seed = _per_episode(full)
        boot = _bootstrap(full, rng)
        full_pooled, sur_pooled = cone_stats(full), cone_stats(sur)
        row: dict[str, Any] = {"weather": weather, "stats": {}, "laps": {},
                               **({"fallback": fallback} if fallback else {})}
        for k in STAT_NAMES:
            lo_s, hi_s = _seed_interval([p[k] for p in per_seed])
            lo_b, hi_b = boot[k]
            los = [v for v in (lo_s, lo_b) if np.isfinite(v)]
            his = [v for v in (hi_s, hi_b) if np.isfinite(v)]
            lo, hi = (min(los), max(his)) if los and his else (math.nan, math.nan)
            lo = max(lo, 0.0)  # every statistic is >= 0, the rates <= 1
            if k.startswith(RATES):
                hi = min(hi, 1.0)
            v = sur_pooled[k]
            ok = None if not (np.isfinite(v) and np.isfinite(lo)) else bool(lo - 1e-9 <= v <= hi + 1e-9)
            row["stats"][k] = {"full": full_pooled[k], "lo": lo, "hi": hi, "surrogate": v, "pass": ok}
        fl, sl = _lap_table(full.episodes), _lap_table(sur.episodes)
        for k in LAP_METRICS:
            fm, fs, sm, ss, ok = _lap_check(fl[k], sl[k])
            row["laps"][k] = {"full_mean": fm, "full_sd": fs, "surrogate_mean": sm, "surrogate_sd": ss, "pass": ok}
        results["rows"].append(row)
    _plots(results, out, overwrite)
    atomic_write(out / "validation.json", to_json(results) + "\n", overwrite=overwrite)
    atomic_write(report, _markdown(results, m), overwrite=overwrite)
    say(f"wrote {report}")
    return results


def _markdown(res: dict[str, Any], model: Any) -> str:
    size = f"; camera {res['camera']}" if res.get("camera") else ""
    if res.get("detector_input"):
        size += f" (detector input {res['detector_input']})"
    lines = [f"# Perception surrogate validation: track {res['track']}", "",
             f"Model `{res['model']}` (fitted on {', '.join(model.meta.get('tracks', []))}){size}; full pipeline seeds "
             f"{res['seeds']}, surrogate seeds {res['surrogate_seeds']}; `mapper_pure_pursuit`, one lap, at most "
             f"{res['steps']} steps. Statistics over cones of at least {res.get('min_box_height_px', MIN_BOX_HEIGHT_PX):g} px (the scored ones); a recall bin with fewer "
             f"than {MIN_CONES} cones is n/a.",
             "", "A cell reads `surrogate (full-pipeline 95 % interval)`, marked **x** when outside.", "",
             "## Cone-list statistics", ""]
    names = list(STAT_NAMES)
    lines.append("| weather | " + " | ".join(names) + " |")
    lines.append("|---|" + "---|" * len(names))
    n_pass = n_all = 0
    for row in res["rows"]:
        cells = []
        for k in names:
            s = row["stats"][k]
            mark = "" if s["pass"] is not False else " **x**"
            if s["pass"] is not None:
                n_all += 1
                n_pass += bool(s["pass"])
            nd = 3 if k.startswith(("range error", "wrong class")) else 2
            cells.append(f"{_fmt(s['surrogate'], nd)} ({_fmt(s['lo'], nd)}-{_fmt(s['hi'], nd)}){mark}")
        lines.append(f"| {row['weather']} | " + " | ".join(cells) + " |")
    notes = [f"* {row['weather']}: {row['fallback']}" for row in res["rows"] if row.get("fallback")]
    if notes:
        lines += ["", "Fallbacks (the surrogate ran clear weather for these):", "", *notes]
    lines += ["", f"Inside the interval: {n_pass} of {n_all} checks.", "", "## Lap metrics (mapper_pure_pursuit)", "",
              "Full pipeline mean +- sd across seeds vs surrogate mean +- sd; **x**: the means differ by more than "
              "2 pooled sd.", "", "| weather | " + " | ".join(LAP_METRICS) + " |", "|---|" + "---|" * len(LAP_METRICS)]
    l_pass = l_all = 0
    for row in res["rows"]:
        cells = []
        for k in LAP_METRICS:
            s = row["laps"][k]
            if s["pass"] is not None:
                l_all += 1
                l_pass += bool(s["pass"])
            mark = "" if s["pass"] is not False else " **x**"
            cells.append(f"{_fmt(s['full_mean'], 2)}+-{_fmt(s['full_sd'], 2)} vs {_fmt(s['surrogate_mean'], 2)}"
                         f"+-{_fmt(s['surrogate_sd'], 2)}{mark}")
        lines.append(f"| {row['weather']} | " + " | ".join(cells) + " |")
    lines += ["", f"Within the spread: {l_pass} of {l_all} checks.", "",
              "![recall by range](recall_by_range.png)", "", "![false positives and miss runs](fp_and_runs.png)", ""]
    return "\n".join(lines)


def _plots(res: dict[str, Any], out: Path, overwrite: bool) -> None:
    matplotlib.use("Agg")


    rows = res["rows"]
    conds = sorted({r["weather"].split("@")[0] for r in rows if r["weather"] != "clear"})
    fig, axes = plt.subplots(1, max(len(conds), 1), figsize=(6 * max(len(conds), 1), 4), squeeze=False)
    x = np.arange(len(BIN_LABELS))
    for ax, cond in zip(axes[0], conds, strict=False):
        mine = [r for r in rows if r["weather"] == "clear" or r["weather"].startswith(cond + "@")]
        for i, r in enumerate(mine):
            color = plt.cm.viridis(i / max(len(mine) - 1, 1))
            st = [r["stats"][f"recall {b}"] for b in BIN_LABELS]
            full = np.array([s["full"] for s in st], float)
            lo = np.array([s["lo"] for s in st], float)
            hi = np.array([s["hi"] for s in st], float)
            ax.fill_between(x, lo, hi, color=color, alpha=0.2)
            ax.plot(x, full, "-", color=color, label=f"{r['weather']} full")
            ax.plot(x, [s["surrogate"] for s in st], "--o", color=color, ms=3, label=f"{r['weather']} surrogate")
        ax.set_xticks(x, BIN_LABELS)
        ax.set_ylim(0, 1)
        ax.set_ylabel("recall")
        ax.set_title(f"{cond}: full pipeline (line, 95 % band) vs surrogate (dashed)")
        ax.legend(fontsize=6, ncol=2)
    save_figure(fig, out / "recall_by_range.png", overwrite=overwrite)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for j, key in enumerate(("FP per frame", "miss run length (frames)")):
        ax = axes[j]
        labels = [r["weather"] for r in rows]
        xs = np.arange(len(rows))
        s = [r["stats"][key] for r in rows]
        ax.errorbar(xs, [v["full"] for v in s],
                    yerr=[[max(v["full"] - v["lo"], 0) for v in s], [max(v["hi"] - v["full"], 0) for v in s]],
                    fmt="o", label="full pipeline (95 % interval)")
        ax.plot(xs, [v["surrogate"] for v in s], "x", color="C3", label="surrogate")
        ax.set_xticks(xs, labels, rotation=45, ha="right", fontsize=7)
        ax.set_title(key)
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "fp_and_runs.png", overwrite=overwrite)


def to_json(results: dict[str, Any]) -> str:
    """The results as JSON (NaN written as null)."""
    def clean(o: Any) -> Any:
        if isinstance(o, float) and not math.isfinite(o):
            return None
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items()}
        if isinstance(o, list):
            return [clean(v) for v in o]
        return o
    return json.dumps(clean(results), indent=1)
