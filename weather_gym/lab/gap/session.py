"""``GapSession``: the sim-versus-measured gap workflow on loaded data, one step at a time.

It holds the measured frames, their clean simulated counterparts (from
:func:`~weather_gym.lab.gap.simulate.simulate`), the fitting and held-out evaluators and the current weather
model; comparing and re-fitting are here, finding and adding effects in
:mod:`~weather_gym.lab.gap.session_search`, the report in :mod:`~weather_gym.lab.gap.session_report`. See
:mod:`weather_gym.lab.gap.workflow` for the loop and the command.

Example:
    >>> [c.__name__ for c in GapSession.__mro__[:3]]
    ['GapSession', 'SearchSteps', 'ReportSteps']
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from tqdm import tqdm

from weather_gym.lab.gap.compare import (
    GapMeter,
    compare_perception,
    compare_perception_did,
    compare_signals,
    gap_test,
    signal_scale,
)
from weather_gym.lab.gap.config import FLOOR_MARGIN, MIN_GAP_CUT, Comparison, GapConfig
from weather_gym.lab.gap.fit import PENALTY, Evaluator, refit, refit_joint
from weather_gym.lab.gap.perception import detect_frames, match_frames, perception_stats
from weather_gym.lab.gap.session_report import ReportSteps, perception_summary
from weather_gym.lab.gap.session_search import SearchSteps
from weather_gym.lab.gap.signals import signal_table, signal_weights
from weather_gym.lab.gap.simulate import GapData
from weather_gym.lab.gap.weather_model import describe
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.labels import SmallRule
from weather_gym.weather import KnobEffect


class GapSession(SearchSteps, ReportSteps):
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
        self.pruned: list[dict[str, Any]] = []
        self.flagged: list[dict[str, Any]] = []
        self.attempts: list[dict[str, Any]] = []
        self.candidates: list[dict[str, Any]] = []
        self._floors: dict[tuple, float] = {}
        self._after_level_cache: dict[tuple, list[str]] = {}
        cfg = self.config
        t0 = time.perf_counter()
        m = data.measured
        self.measured_signals = signal_table(m.images, data.signal_depths("measured"), data.signal_boxes("measured"),
                                             data.signal_masks("measured"))
        self.reference_signals = None
        if data.did:
            r = data.reference
            self.reference_signals = signal_table(r.images, data.signal_depths("reference"),  # type: ignore[union-attr]  # DiD: a reference
                                                  data.signal_boxes("reference"), data.signal_masks("reference"))
        self.scale = signal_scale(self.measured_signals)
        self.weights = signal_weights()
        rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0xF17]))
        fit_sim = data.sim_fit
        if len(fit_sim) > cfg.fit_frames:
            fit_sim = np.sort(rng.choice(fit_sim, cfg.fit_frames, replace=False))
        fit_meas = fit_sim if data.paired else data.fit
        self._fit_idx = (np.asarray(fit_sim), np.asarray(fit_meas))
        fit_ref = (fit_meas if data.ref_paired else data.ref_fit) if data.did else None
        self.fit_ev = self._evaluator(fit_sim, fit_meas, fit_ref)
        self.held_ev = self._evaluator(data.sim_held, data.held, data.ref_held if data.did else None)
        self.timings["signals_measured_s"] = time.perf_counter() - t0
        self._detector = None
        self._fixed_matches: dict[str, Any] = {}
        self._comparisons: dict[tuple, Comparison] = {}

    # ------------------------------------------------------------------ plumbing
    def _evaluator(self, sim_idx: np.ndarray, meas_idx: np.ndarray, ref_idx: np.ndarray | None = None) -> Evaluator:
        d, s = self.data, self.data.sim
        depths, boxes, masks = d.signal_depths("sim"), d.signal_boxes("sim"), d.signal_masks("sim")
        meter = GapMeter(self.measured_signals[meas_idx], scale=self.scale, weights=self.weights, paired=d.paired,
                         reference=None if ref_idx is None else self.reference_signals[ref_idx],  # type: ignore[index]  # DiD
                         ref_paired=d.ref_paired)
        ev = Evaluator([s.images[i] for i in sim_idx], [s.depths[i] for i in sim_idx],
                       [s.states[i] for i in sim_idx], [s.ids[i] for i in sim_idx],
                       [depths[i] for i in sim_idx], [boxes[i] for i in sim_idx], meter, seed=self.config.seed,
                       signal_masks=[masks[i] for i in sim_idx])
        if meter.did:
            meter.base = ev.signals([])  # the clean simulator frames: the baseline of the simulated change
        return ev

    def _say(self, msg: str) -> None:
        self.log.append(msg)
        if self.config.progress:
            tqdm.write(f"gap: {msg}")

    @property
    def detector(self):
        if self._detector is None:
            self._detector = load_detector(self.config.detector, threads=1)
        return self._detector

    @property
    def min_box_height(self) -> float:
        """The too-small rule at the comparison size and the detector's input scale (image pixels)."""

        return SmallRule.for_image(self.data.measured.size, self.detector).min_height_px

    def _match(self, images: Sequence[np.ndarray], gts: Sequence[dict]):
        dets = detect_frames(self.detector, images)
        return match_frames(gts, dets, score_threshold=self.detector.score_threshold,
                            min_box_height=self.min_box_height)

    def _fixed(self, which: str):
        """Detector matches of a set that no model changes: the held-out measured (and reference) frames."""
        if which not in self._fixed_matches:
            d = self.data
            frames, idx = (d.measured, d.held) if which == "measured" else (d.reference, d.ref_held)
            self._fixed_matches[which] = self._match([frames.images[i] for i in idx], [frames.gts[i] for i in idx])  # type: ignore[union-attr]  # the set exists in this mode
        return self._fixed_matches[which]

    def _measured_perception(self):
        return self._fixed("measured")

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
            gts = [self.data.sim.gts[i] for i in self.data.sim_held]
            sm = self._match(self.held_ev.frames(model), gts)
            mm = self._measured_perception()
            if self.data.did:
                if "sim_clean" not in self._fixed_matches:
                    self._fixed_matches["sim_clean"] = self._match(self.held_ev.frames([]), gts)
                prow, st = compare_perception_did(sm, self._fixed_matches["sim_clean"], mm, self._fixed("reference"),
                                                  ref_paired=self.data.ref_paired, seed=cfg.seed, alpha=cfg.alpha)
                comp.perception_rows = prow
                comp.perception = perception_summary(prow, st["sim"], st["measured"], st["sim_clean"],
                                                      st["reference"])
            else:
                prow = compare_perception(sm, mm, paired=self.data.paired, seed=cfg.seed, alpha=cfg.alpha)
                comp.perception_rows = prow
                comp.perception = perception_summary(prow, perception_stats(sm), perception_stats(mm))
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

    def step(self) -> dict[str, Any] | None:
        """One iteration: stop if nothing disagrees; else re-fit, diagnose and try to add the best."""
        comp = self.compare(perception=False)
        if not comp.significant:
            self._say("no significant disagreement on the held-out frames")
            return None
        self._say(f"held-out gap {comp.gap:.3f}; disagreeing: {', '.join(comp.significant[:6])}")
        floor = self.floor()
        if not self.data.paired and comp.gap <= FLOOR_MARGIN * floor:
            self._say(f"held-out gap {comp.gap:.3f} at the unpaired floor {floor:.3f} (clear against clear): "
                      "what is left cannot be told without poses")
            return None
        self.refit()
        if not self.compare(perception=False).significant:
            return None
        if len(self.steps) >= self.config.max_steps:
            return None
        found = self.diagnose()
        if not found:
            self._say("no candidate lowers the gap on the fitting frames")
            return None
        found = self.rank(found + self.measure(found))
        for cand in found:  # best first; a candidate flagged for a fit on a bound gives way to the next
            n_flagged = len(self.flagged)
            step = self.add(cand, found)
            if step is not None or len(self.flagged) == n_flagged:
                return step
        return None

    def prune(self) -> list[dict[str, Any]]:
        """Parsimony: try removing each effect the loop added (re-fitting the others without it); drop
        it when the held-out gap without it is not significantly worse (bootstrap p >= alpha, less than PENALTY worse, or worse by less than
        :data:`MIN_GAP_CUT`), the weakest
        first, until every remaining one earns its place. Returns one record per dropped effect."""
        t0 = time.perf_counter()
        cfg = self.config
        dropped = []
        while True:
            added = [st["added"]["name"] for st in self.steps
                     if st["added"]["name"] in {e.name for e in self.model}
                     and st["added"]["name"] not in {p["name"] for p in self.pruned}]
            weakest = None
            for name in added:
                without = [e for e in self.model if e.name != name]
                if without:  # the others re-fitted without it: they may take over what it did
                    without, _ = refit_joint(self.fit_ev, without)
                test = gap_test(self.held_ev.meter, self.held_ev.signals(without), self.held_ev.signals(self.model),
                                b=cfg.bootstrap, seed=cfg.seed)
                earns = (test["p_value"] < cfg.alpha and test["gap_after"] <= (1.0 - PENALTY) * test["gap_before"]
                         and test["gap_before"] - test["gap_after"] >= MIN_GAP_CUT)
                if not earns and (weakest is None or test["p_value"] > weakest[2]["p_value"]):
                    weakest = (name, without, test)
            if weakest is None:
                break
            name, without, test = weakest
            self._say(f"parsimony: without {name} the held-out gap is {test['gap_before']:.3f} against "
                      f"{test['gap_after']:.3f} with it (p = {test['p_value']:.4f}): not significantly worse, dropped")
            rec = {"name": name, "gap_without": test["gap_before"], "gap_with": test["gap_after"],
                   "p_value": test["p_value"], "params": next(e.params() for e in self.model if e.name == name)}
            self.model = without
            self.pruned.append(rec)
            dropped.append(rec)
            self.history.append((f"- {name}", list(self.model)))
        if dropped and self.model:
            self.refit()
        self.timings["prune_s"] = self.timings.get("prune_s", 0.0) + time.perf_counter() - t0
        return dropped

    def run(self) -> dict[str, Any]:
        """The whole loop (until no candidate helps significantly), then parsimony; returns the report
        dict. Confounded data (a real recording without a clear reference) is compared and its
        differences reported, but nothing is fitted as weather."""
        t0 = time.perf_counter()
        first = self.compare()
        if self.data.confounded:
            self._say("confounded: " + self.data.confounded_reason)
        else:
            while self.step() is not None:
                pass
            if self.config.prune:
                self.prune()
        last = self.compare()
        self.timings["loop_s"] = time.perf_counter() - t0
        return self.report(first, last)
