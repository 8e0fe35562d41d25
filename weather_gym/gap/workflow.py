"""The sim-versus-measured gap workflow: compare, name the missing effect, add it, show the gap shrink.

:class:`GapSession` holds the measured frames, their clean simulated counterparts (from
:func:`~weather_gym.gap.simulate.simulate`) and the current weather model, and runs one step at a
time, for notebooks::

    data = simulate("data/measured", cache_dir="out/cache")
    s = GapSession(data, read_model("model.toml"))
    s.compare()          # held-out disagreements, image gap, perception gap of the current model
    s.refit()            # re-fit the parameters of the effects already in the model
    found = s.diagnose() # fit every candidate effect; best first, with held-out gaps
    s.add(found[0])      # add it (after checking it is significant), returns the step record
    s.run()              # the whole loop, returns the report dict

:func:`run_gap` is the command: it loads the inputs, runs the loop and writes ``report.json``,
``model.toml``, ``report.md`` and the plots into the output folder.

Selection is driven by the image-signal gap (:mod:`~weather_gym.gap.compare`): it is sensitive
(per-frame differences in paired mode) and it tells effects apart; the detector's mAP is one
number that many different effects can move by the same amount, and it is noisy on a few hundred
frames. The perception gap (``|mAP_sim - mAP_measured|`` at IoU 0.5, per class, recall by range
and box size, score distributions) is reported first, before and after every step.

Example:
    >>> from weather_gym.gap.workflow import GapConfig
    >>> GapConfig().held_out
    0.5
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym._io import atomic_write_json
from weather_gym.errors import InputError
from weather_gym.gap.compare import (
    ALPHA,
    MIN_EFFECT,
    GapMeter,
    compare_perception,
    compare_signals,
    gap_test,
    signal_scale,
)
from weather_gym.gap.diagnose import evidence, significant_signals
from weather_gym.gap.fit import (
    PENALTY,
    Evaluator,
    FitResult,
    candidates,
    fit,
    fit_summary,
    refit,
    refit_joint,
    screen,
)
from weather_gym.gap.model import describe, model_tables, read_model, write_model
from weather_gym.gap.perception import detect_frames, match_frames, perception_stats
from weather_gym.gap.signals import SIGNAL_NAMES, signal_table, signal_weights
from weather_gym.gap.simulate import GapData, simulate
from weather_gym.weather import KnobEffect

__all__ = ["GapConfig", "Comparison", "GapSession", "run_gap", "REPORT_VERSION"]

REPORT_VERSION = 1


@dataclass(frozen=True)
class GapConfig:
    """Settings of a gap run (all have defaults; the CLI exposes the common ones).

    Attributes:
        seed: seeds the split, the bootstrap and every effect's random numbers.
        mode: ``auto`` / ``paired`` / ``unpaired``.
        tracks: tracks to render in unpaired mode (default: the records' tracks).
        sim_frames: frames to render in unpaired mode (default: as many as measured).
        held_out: fraction of the frames held out for the reported gaps.
        fit_frames: at most this many fitting frames are used by the parameter search.
        max_steps: at most this many effects are added.
        candidates: effect names that may be added (default: every registered effect).
        top: candidates fully fitted per step (the best of the k-grid screening).
        alpha: family-wise significance level (Holm) of disagreements and of a step.
        min_effect: smallest standardised bias reported as a disagreement.
        bootstrap: bootstrap resamples of the image signals (perception uses 300).
        perception: run the detector (the report's perception level).
        detector: ONNX model path (default: the shipped detector).
    """

    seed: int = 0
    mode: str = "auto"
    tracks: tuple[str, ...] | None = None
    sim_frames: int | None = None
    held_out: float = 0.5
    fit_frames: int = 32
    max_steps: int = 4
    candidates: tuple[str, ...] | None = None
    top: int = 2
    alpha: float = ALPHA
    min_effect: float = MIN_EFFECT
    bootstrap: int = 1000
    perception: bool = True
    detector: str | None = None
    progress: bool = False

    def __post_init__(self) -> None:
        from weather_gym.weather import EFFECTS

        if not 0.0 < self.held_out < 1.0:
            raise InputError(f"held_out must be a fraction in (0, 1), got {self.held_out}")
        if self.mode not in ("auto", "paired", "unpaired"):
            raise InputError(f"mode must be 'auto', 'paired' or 'unpaired', got {self.mode!r}")
        if self.sim_frames is not None and self.sim_frames < 4:
            raise InputError(f"sim_frames must be >= 4, got {self.sim_frames}")
        if self.fit_frames < 4:
            raise InputError(f"fit_frames must be >= 4, got {self.fit_frames}")
        if self.max_steps < 0:
            raise InputError(f"max_steps must be >= 0, got {self.max_steps}")
        if self.top < 1:
            raise InputError(f"top must be >= 1, got {self.top}")
        if not 0.0 < self.alpha < 1.0:
            raise InputError(f"alpha must be in (0, 1), got {self.alpha}")
        if self.bootstrap < 100:
            raise InputError(f"bootstrap must be >= 100 resamples, got {self.bootstrap}")
        for name in self.candidates or ():
            EFFECTS.get(name)  # unknown names: ValueError listing the valid ones


@dataclass
class Comparison:
    """A model compared with the measured frames on the held-out frames."""

    model: list[KnobEffect]
    signals: np.ndarray
    rows: list[dict[str, Any]]
    gap: float
    perception_rows: list[dict[str, Any]] | None = None
    perception: dict[str, Any] | None = None

    @property
    def significant(self) -> list[str]:
        """Image signals that disagree significantly, strongest first."""
        return significant_signals(self.rows)

    @property
    def perception_gap(self) -> float:
        return math.nan if self.perception is None else self.perception["abs_diff"]

    def disagreements(self) -> list[dict[str, Any]]:
        """Perception rows then image rows, each group strongest first (the report's list)."""
        def order(rows):
            return sorted(rows, key=lambda r: (not r["significant"], -_finite_abs(r["effect_size"])))

        return order(self.perception_rows or []) + order(self.rows)


def _finite_abs(v: float) -> float:
    return abs(v) if v is not None and math.isfinite(v) else -1.0


class GapSession:
    """The workflow on loaded data, one step at a time (see module doc)."""

    def __init__(self, data: GapData, model: Sequence[KnobEffect], config: GapConfig | None = None) -> None:
        self.data = data
        self.config = config or GapConfig()
        self.input_model = list(model)
        self.model = list(model)
        self.steps: list[dict[str, Any]] = []
        self.refits: list[dict[str, Any]] = []
        self.history: list[tuple[str, list[KnobEffect]]] = [("input model", list(model))]
        self.timings: dict[str, float] = {}
        self.log: list[str] = []
        cfg = self.config
        t0 = time.perf_counter()
        m = data.measured
        depths_m, boxes_m = data.signal_depths("measured"), data.signal_boxes("measured")
        self.measured_signals = signal_table(m.images, depths_m, boxes_m)
        self.scale = signal_scale(self.measured_signals)
        self.weights = signal_weights()
        rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0xF17]))
        fit_sim = data.sim_fit
        if len(fit_sim) > cfg.fit_frames:
            fit_sim = np.sort(rng.choice(fit_sim, cfg.fit_frames, replace=False))
        fit_meas = fit_sim if data.paired else data.fit
        self.fit_ev = self._evaluator(fit_sim, fit_meas)
        self.held_ev = self._evaluator(data.sim_held, data.held)
        self.timings["signals_measured_s"] = time.perf_counter() - t0
        self._detector = None
        self._measured_matches = None
        self._comparisons: dict[tuple, Comparison] = {}

    # ------------------------------------------------------------------ plumbing
    def _evaluator(self, sim_idx: np.ndarray, meas_idx: np.ndarray) -> Evaluator:
        d, s = self.data, self.data.sim
        depths, boxes = d.signal_depths("sim"), d.signal_boxes("sim")
        meter = GapMeter(self.measured_signals[meas_idx], scale=self.scale, weights=self.weights, paired=d.paired)
        return Evaluator([s.images[i] for i in sim_idx], [s.depths[i] for i in sim_idx],
                         [s.states[i] for i in sim_idx], [s.ids[i] for i in sim_idx],
                         [depths[i] for i in sim_idx], [boxes[i] for i in sim_idx], meter, seed=self.config.seed)

    def _say(self, msg: str) -> None:
        self.log.append(msg)
        if self.config.progress:
            from tqdm import tqdm

            tqdm.write(f"gap: {msg}")

    @property
    def detector(self):
        if self._detector is None:
            from weather_gym.perception import ConeDetector

            self._detector = ConeDetector(self.config.detector, threads=1)
        return self._detector

    def _measured_perception(self):
        if self._measured_matches is None:
            m = self.data.measured
            ims = [m.images[i] for i in self.data.held]
            dets = detect_frames(self.detector, ims)
            self._measured_matches = match_frames([m.gts[i] for i in self.data.held], dets,
                                                  score_threshold=self.detector.score_threshold)
        return self._measured_matches

    # ------------------------------------------------------------------ steps
    def compare(self, model: Sequence[KnobEffect] | None = None, *, perception: bool | None = None) -> Comparison:
        """Compare ``model`` (default: the current one) with the measured frames on the held-out frames."""
        model = self.model if model is None else list(model)
        perception = self.config.perception if perception is None else perception
        key = (tuple((e.name, tuple(sorted(e.params().items()))) for e in model), perception)
        if key in self._comparisons:
            return self._comparisons[key]
        t0 = time.perf_counter()
        cfg = self.config
        sig = self.held_ev.signals(model)
        rows = compare_signals(self.held_ev.meter, sig, b=cfg.bootstrap, seed=cfg.seed, alpha=cfg.alpha,
                               min_effect=cfg.min_effect)
        comp = Comparison(model, sig, rows, self.held_ev.meter.gap(sig))
        if perception:
            frames = self.held_ev.frames(model)
            dets = detect_frames(self.detector, frames)
            gts = [self.data.sim.gts[i] for i in self.data.sim_held]
            sm = match_frames(gts, dets, score_threshold=self.detector.score_threshold)
            mm = self._measured_perception()
            prow = compare_perception(sm, mm, paired=self.data.paired, seed=cfg.seed, alpha=cfg.alpha)
            comp.perception_rows = prow
            comp.perception = _perception_summary(prow, perception_stats(sm), perception_stats(mm))
        self.timings["compare_s"] = self.timings.get("compare_s", 0.0) + time.perf_counter() - t0
        self._comparisons[key] = comp
        return comp

    def refit(self) -> list[dict[str, Any]]:
        """Re-fit the effects already in the model: each one alone (k grid, Brent, extras), then all
        together (least squares over every k and moved parameter).

        The new settings are kept only when they shrink the held-out gap significantly (bootstrap
        p < alpha) and by at least PENALTY (relative): before the missing effects are found, a k
        may otherwise drift to stand in for them. Returns one record per effect that changed.
        """
        t0 = time.perf_counter()
        old = list(self.model)
        new = list(old)
        for i in range(len(new)):
            r = refit(self.fit_ev, new, i)
            if r.effect.params() != new[i].params():
                new[i] = r.effect
        if len(new) > 1:
            new, _ = refit_joint(self.fit_ev, new)
        done: list[dict[str, Any]] = []
        if [e.params() for e in new] != [e.params() for e in old]:
            before, after = self.held_ev.signals(old), self.held_ev.signals(new)
            test = gap_test(self.held_ev.meter, before, after, b=self.config.bootstrap, seed=self.config.seed)
            ok = test["p_value"] < self.config.alpha and test["gap_after"] <= (1.0 - PENALTY) * test["gap_before"]
            verdict = "kept" if ok else f"not kept (needs p < {self.config.alpha} and a {PENALTY:.0%} cut)"
            self._say(f"re-fit {', '.join(describe(e) for e in new)}: held-out gap {test['gap_before']:.3f} -> "
                      f"{test['gap_after']:.3f} (p = {test['p_value']:.4f}), {verdict}")
            if ok:
                for e0, e1 in zip(old, new):
                    if e0.params() == e1.params():
                        continue
                    rec = {"name": e0.name, "params_before": e0.params(), "params_after": e1.params(),
                           "changed": {p: [e0.params()[p], v] for p, v in e1.params().items() if e0.params()[p] != v},
                           "gap_before": test["gap_before"], "gap_after": test["gap_after"],
                           "p_value": test["p_value"], "step": len(self.steps)}
                    self.refits.append(rec)
                    done.append(rec)
                self.model = new
                self.history.append(("re-fit " + ", ".join(r["name"] for r in done), list(self.model)))
        self.timings["refit_s"] = self.timings.get("refit_s", 0.0) + time.perf_counter() - t0
        return done

    def diagnose(self, names: Sequence[str] | None = None) -> list[dict[str, Any]]:
        """Fit every candidate effect (k grid, then the best ``top`` fully); best first.

        Each entry: ``fit`` (a :class:`~weather_gym.gap.fit.FitResult`), ``model`` (the current
        model with it inserted), ``held_gap`` and ``penalized`` (held-out gap times 1 + PENALTY per
        parameter), plus ``screened``: every candidate's best k on the grid.
        """
        from tqdm import tqdm

        t0 = time.perf_counter()
        names = names if names is not None else self.config.candidates
        cands = candidates(self.model, names)
        screened: list[FitResult] = []
        for c in tqdm(cands, desc="screen", unit="effect", disable=not self.config.progress, leave=False):
            screened.append(screen(self.fit_ev, self.model, c))
        g_now = self.fit_ev.gap(self.model)
        useful = sorted((r for r in screened if r.fit_gap < g_now), key=lambda r: (r.fit_gap, r.candidate.describe()))
        out = []
        for r in useful[:self.config.top]:
            f = fit(self.fit_ev, self.model, r)
            model = self.model[:f.position] + [f.effect] + self.model[f.position:]
            g_held = self.held_ev.gap(model)
            out.append({"fit": f, "model": model, "held_gap": g_held, "fit_gap_before": g_now,
                        "penalized": g_held * (1.0 + PENALTY * f.n_params)})
        out.sort(key=lambda e: (e["penalized"], e["fit"].candidate.describe()))
        screening = [{"candidate": r.candidate.describe(), "k": r.effect.k, "fit_gap": r.fit_gap,
                      "curve": [[k, g] for k, g in r.curve]} for r in screened]
        for e in out:
            e["screened"] = screening
        self._last_screening = screening
        self.timings["diagnose_s"] = self.timings.get("diagnose_s", 0.0) + time.perf_counter() - t0
        return out

    def add(self, found: dict[str, Any], alternatives: Sequence[dict[str, Any]] = (), *,
            force: bool = False) -> dict[str, Any] | None:
        """Add a candidate from :meth:`diagnose` if it shrinks the held-out gap significantly.

        Significant: the bootstrap p-value of "the reduction is not positive" is below ``alpha``
        divided by the number of candidates fully fitted, and the gap falls by at least PENALTY per
        parameter. Returns the step record, or None (nothing added) unless ``force``.
        """
        cfg = self.config
        f: FitResult = found["fit"]
        before = self.compare()
        after = self.compare(found["model"])
        test = gap_test(self.held_ev.meter, before.signals, after.signals, b=cfg.bootstrap, seed=cfg.seed)
        n_tested = max(len(alternatives), 1)
        needed = 1.0 - PENALTY * f.n_params
        ev = evidence(before.rows, after.rows, f.effect.name)
        ok = test["p_value"] < cfg.alpha / n_tested and test["gap_after"] <= needed * test["gap_before"]
        why = "added" if ok else "not significant"
        if ok and not (ev["fixed"] or ev["improved"]):
            ok, why = False, "fixes no significant disagreement"
        what = describe(f.effect)
        self._say(f"best candidate {what}: held-out gap {test['gap_before']:.3f} -> {test['gap_after']:.3f} "
                  f"(p = {test['p_value']:.4f}, {why})")
        if not ok and not force:
            return None
        step = {
            "added": {"name": f.effect.name, "params": f.effect.params(), "describe": what},
            "position": f.position,
            "gap_before": test["gap_before"], "gap_after": test["gap_after"],
            "gap_before_ci95": test["gap_before_ci95"], "gap_after_ci95": test["gap_after_ci95"],
            "reduction_ci95": test["reduction_ci95"], "p_value": test["p_value"],
            "n_params": f.n_params, "fitted_extras": f.extras, "fit_gap": f.fit_gap,
            "fit_gap_before": found.get("fit_gap_before"),
            "perception_gap_before": before.perception_gap, "perception_gap_after": after.perception_gap,
            "perception_before": before.perception, "perception_after": after.perception,
            "evidence": ev,
            "alternatives": [{"candidate": a["fit"].candidate.describe(), "describe": describe(a["fit"].effect),
                              "held_gap": a["held_gap"], "penalized": a["penalized"], "fit_gap": a["fit"].fit_gap,
                              "n_params": a["fit"].n_params} for a in alternatives],
            "screening": found.get("screened", []),
            "fit": fit_summary(f),
        }
        self.model = found["model"]
        self.steps.append(step)
        self.history.append((f"+ {f.effect.name}", list(self.model)))
        return step

    def step(self) -> dict[str, Any] | None:
        """One iteration: stop if nothing disagrees; else re-fit, diagnose and try to add the best."""
        comp = self.compare(perception=False)
        if not comp.significant:
            self._say("no significant disagreement on the held-out frames")
            return None
        self._say(f"held-out gap {comp.gap:.3f}; disagreeing: {', '.join(comp.significant[:6])}")
        self.refit()
        if not self.compare(perception=False).significant:
            return None
        if len(self.steps) >= self.config.max_steps:
            return None
        found = self.diagnose()
        if not found:
            self._say("no candidate lowers the gap on the fitting frames")
            return None
        return self.add(found[0], found)

    def run(self) -> dict[str, Any]:
        """The whole loop (until no candidate helps significantly); returns the report dict."""
        t0 = time.perf_counter()
        first = self.compare()
        while self.step() is not None:
            pass
        last = self.compare()
        self.timings["loop_s"] = time.perf_counter() - t0
        return self.report(first, last)

    # ------------------------------------------------------------------ report
    def stages(self) -> list[dict[str, Any]]:
        """Held-out gaps after each change, in order: input model, re-fits, added effects."""
        out = []
        for label, model in self.history:
            c = self.compare(model)
            out.append({"label": label, "model": model_tables(model), "gap": c.gap, "perception_gap": c.perception_gap,
                        "map50_sim": None if c.perception is None else c.perception["map50_sim"],
                        "map50_measured": None if c.perception is None else c.perception["map50_measured"],
                        "map50_diff_ci95": None if c.perception is None else c.perception["diff_ci95"]})
        return out

    def report(self, first: Comparison | None = None, last: Comparison | None = None) -> dict[str, Any]:
        """The report dict (``report.json``'s content, without file paths)."""
        first = first or self.compare(self.input_model)
        last = last or self.compare()
        d = self.data
        return {
            "version": REPORT_VERSION,
            "mode": d.mode,
            "mode_reason": d.mode_reason,
            "notes": list(d.notes),
            "frames": {"measured": len(d.measured), "simulated": len(d.sim), "fit": int(len(d.fit)),
                       "held_out": int(len(d.held)), "fit_used": len(self.fit_ev), "size": list(d.measured.size),
                       "tracks": d.meta.get("tracks", [])},
            "gap_metric": {
                "name": "image_signal_rms",
                "description": "weighted RMS of the standardised biases (sim - measured) / sigma of the image "
                               "signals, every signal family weighing the same; held-out frames; lower is better",
                "drives_selection": True,
                "perception_metric": "|mAP@0.5 sim - mAP@0.5 measured| on the held-out frames (reported first)",
            },
            "gap_before": first.gap,
            "gap_after": last.gap,
            "perception_gap_before": first.perception_gap,
            "perception_gap_after": last.perception_gap,
            "perception_before": first.perception,
            "perception_after": last.perception,
            "disagreements": first.disagreements(),
            "disagreements_after": last.disagreements(),
            "refits": self.refits,
            "steps": self.steps,
            "stages": self.stages(),
            "missing_effects": [s["added"]["name"] for s in self.steps],
            "model_in": model_tables(self.input_model),
            "model_effects": model_tables(self.model),
            "signals": [{"name": n, "scale": float(s)} for n, s in zip(SIGNAL_NAMES, self.scale)],
            "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self.config).items()
                         if k != "progress"},
            "log": list(self.log),
        }


def _perception_summary(rows: list[dict[str, Any]], sim: dict[str, float], meas: dict[str, float]) -> dict[str, Any]:
    by = {r["signal"]: r for r in rows}
    m = by["map50"]
    return {
        "map50_sim": sim["map50"], "map50_measured": meas["map50"], "diff": m["difference"],
        "abs_diff": abs(m["difference"]) if math.isfinite(m["difference"]) else math.nan,
        "diff_ci95": m["ci95"], "significant": m["significant"],
        "per_class": {n.split(".", 1)[1]: {"sim": sim[n], "measured": meas[n]} for n in sim if n.startswith("ap50.")},
        "recall_by_range": {n.split(".", 2)[2]: {"sim": sim[n], "measured": meas[n]}
                            for n in sim if n.startswith("recall.range.")},
        "recall_by_size": {n.split(".", 2)[2]: {"sim": sim[n], "measured": meas[n]}
                           for n in sim if n.startswith("recall.size.")},
        "scores": {n: {"sim": sim[n], "measured": meas[n]} for n in ("score_tp_mean", "score_fp_mean", "fp_per_frame")},
    }


def _changes(before: dict[str, Any], after: dict[str, Any]) -> str:
    """``"k 0.3 -> 0.5329, ..."`` for the parameters that differ."""
    return ", ".join(f"{p} {before[p]:.4g} -> {v:.4g}" if isinstance(v, float) else f"{p} {before[p]} -> {v}"
                     for p, v in after.items() if p in before and before[p] != v)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    return x


def run_gap(measured: str | os.PathLike, model: str | os.PathLike | None, out: str | os.PathLike,
            config: GapConfig | None = None, *, cache_dir: str | os.PathLike | None = None,
            overwrite: bool = False, plots: bool = True) -> dict[str, Any]:
    """Run the whole workflow and write ``report.json``, ``model.toml``, ``report.md`` and plots to ``out``.

    ``model`` None is the clean simulator. The clean renders are cached in ``cache_dir`` (default
    ``out/cache``); an existing report in ``out`` is never overwritten unless ``overwrite``.
    Returns the report dict as written to ``report.json``.
    """
    from weather_gym.gap.report import write_markdown, write_plots

    config = config or GapConfig()
    out = Path(out)
    t_start = time.perf_counter()
    from weather_gym._io import check_output
    from weather_gym.gap.report import PLOT_NAMES

    for name in ("report.json", "model.toml", "report.md", *(PLOT_NAMES if plots else ())):
        check_output(out / name, overwrite=overwrite)
    effects = read_model(model) if model is not None else []
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(cache_dir) if cache_dir is not None else out / "cache"
    t0 = time.perf_counter()
    data = simulate(measured, cache_dir=cache, mode=config.mode, tracks=list(config.tracks) if config.tracks else None,
                    sim_frames=config.sim_frames, held_out=config.held_out, seed=config.seed,
                    progress=config.progress)
    t_sim = time.perf_counter() - t0
    session = GapSession(data, effects, config)
    report = session.run()
    model_path = out / "model.toml"
    comments = {}
    for i, e in enumerate(session.model):
        step = next((s for s in session.steps if s["added"]["name"] == e.name), None)
        if step is not None:
            fixed = ", ".join(step["evidence"]["fixed"][:4]) or "-"
            comments[i] = (f"added by weather-gym gap: held-out gap {step['gap_before']:.3g} -> "
                           f"{step['gap_after']:.3g}; fixes {fixed}")
            first = step["added"]["params"]
        else:
            first = next((x.params() for x in session.input_model if x.name == e.name), None)
            if first is None:
                continue
        changed = _changes(first, e.params())
        if changed:
            comments[i] = (comments[i] + f"; re-fitted since: {changed}" if i in comments
                           else f"re-fitted by weather-gym gap: {changed}")
    write_model(model_path, session.model, comments,
                header=f"weather model written by `weather-gym gap` from {model if model is not None else 'the clean simulator'}\n"
                       f"measured data: {data.meta['measured']} ({data.mode} mode)", overwrite=overwrite)
    report["measured"] = str(measured)
    report["model_input"] = None if model is None else str(model)
    report["model"] = str(model_path)
    session.timings["simulate_s"] = t_sim
    report["plots"] = write_plots(report, session, out, overwrite=overwrite) if plots else []
    session.timings["total_s"] = time.perf_counter() - t_start
    report["timings"] = {k: round(v, 2) for k, v in sorted(session.timings.items())}
    report = _jsonable(report)
    atomic_write_json(out / "report.json", report, indent=1, overwrite=overwrite)
    write_markdown(report, out / "report.md", overwrite=overwrite)
    return report
