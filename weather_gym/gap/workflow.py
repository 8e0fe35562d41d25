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
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from weather_gym._io import atomic_write_json, check_output, exclusive
from weather_gym.camera_isp import CameraModel
from weather_gym.errors import InputError
from weather_gym.gap.compare import (
    ALPHA,
    MIN_EFFECT,
    GapMeter,
    compare_perception,
    compare_perception_did,
    compare_signals,
    gap_test,
    signal_scale,
)
from weather_gym.gap.diagnose import evidence, significant_signals
from weather_gym.gap.domain import clutter, compare_clutter, ego_vehicle, name_differences
from weather_gym.gap.fit import (
    PENALTY,
    Candidate,
    Evaluator,
    FitResult,
    _brent,
    bounds_hit,
    candidates,
    fit,
    fit_summary,
    refit,
    refit_joint,
    screen,
)
from weather_gym.gap.measured import KIND, MEASURED, MEASURED_PARAMS, PARTNERS, estimate, shape_text
from weather_gym.gap.perception import detect_frames, match_frames, perception_stats
from weather_gym.gap.report import PLOT_NAMES, write_markdown, write_plots
from weather_gym.gap.signals import SIGNAL_NAMES, SIGNALS, signal_table, signal_weights
from weather_gym.gap.simulate import COMPARE_WIDTH, MIN_FRAMES, MODES, GapData, simulate
from weather_gym.gap.weather_model import describe, insert_position, model_tables, read_model, write_model
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.labels import SmallRule
from weather_gym.sim.config import SCENES
from weather_gym.weather import EFFECTS, KnobEffect

__all__ = ["GapConfig", "Comparison", "GapSession", "run_gap", "REPORT_VERSION"]

REPORT_VERSION = 2

MIN_GAP_CUT = 0.1
"""Smallest held-out gap cut (in scene-to-scene spreads) for which an effect is added or kept."""

CLIP_EXPLAINS = 0.5
"""A fit clipped by its family's range is still added (flagged :data:`BEYOND_RANGE`) when it takes the
held-out gap to at most this fraction of what it was: the family is right, the model needs more of it."""

BEYOND_RANGE = "the measured effect goes beyond this family's range"

#: the evidence an effect cannot be named without (its fingerprint): at least one of these signals or
#: signal families must disagree. ``dim`` darkens the frame, so noise alone (or noise that only moves
#: the extreme percentiles) is not dim; each kind's effects need their kind's signals; ``glare`` (a
#: veil and bloom) is never a fix for the noise signals alone
REQUIRES: dict[str, tuple[str, ...]] = {"dim": ("brightness", "tone_p50"), "exposure": ("tone",), "tone_curve": ("tone",),
                                        "noise": ("noise",), "noise_level": ("noise",), "vignette": ("vignette",),
                                        "radial_gain": ("vignette",), "glare": ("blobs", "tone", "haze"),
                                        "blur_kernel": ("sharpness", "motion", "cones")}
#: the parametric and measured effects of each kind
KIND_EFFECTS: dict[str, tuple[str, ...]] = {"tone": ("exposure", "tone_curve"), "noise": ("noise", "noise_level"),
                                            "sharpness": ("blur", "blur_kernel"), "motion": ("motion_blur",),
                                            "vignette": ("vignette", "radial_gain")}
#: the signal family that is each effect's main fingerprint (for the verdict's advice)
EFFECT_FAMILY: dict[str, str] = {"blur": "sharpness", "motion_blur": "motion", "noise": "noise", "noise_level": "noise",
                                 "exposure": "tone", "dim": "tone", "tone_curve": "tone", "fog": "haze",
                                 "vignette": "vignette", "radial_gain": "vignette", "jpeg": "block",
                                 "droplets": "blobs", "glare": "blobs", "rain": "blobs", "blur_kernel": "sharpness"}
#: signal families whose disagreement lets a measured member be measured (default: its kind)
MEASURED_KINDS: dict[str, tuple[str, ...]] = {"blur_kernel": ("sharpness", "motion")}
#: effects that change every pixel alike (no dependence on the distance from the centre)
GLOBAL_TONE = ("exposure", "dim", "tone_curve")
EVIDENCE_MARGIN = 2.0
"""A radial candidate within this factor of a global tone change's penalised gap is named before it
when the fall-off to the corners disagrees."""

PERCEPTION_MIN_MAP = 0.3
"""Below this mAP@0.5 on the measured clear frames the perception gap means nothing (the report says so)."""


@dataclass(frozen=True)
class GapConfig:
    """Settings of a gap run (all have defaults; the CLI exposes the common ones).

    Attributes:
        seed: seeds the split, the bootstrap and every effect's random numbers.
        mode: ``auto`` / ``paired`` / ``unpaired`` / ``same-camera`` / ``did`` (the last two need a
            clear reference; see :func:`~weather_gym.gap.simulate.simulate`).
        tracks: tracks to render in unpaired and did modes (default: the records' tracks).
        sim_frames: frames to render in unpaired / did mode (default: as many as measured).
        scene: the simulator world of unpaired / did renders (``"plain"`` or ``"realistic"``; default: the
            one the records name, else the default world).
        camera_model: the camera model of unpaired / did renders (a ``CameraModel``; default: the one the
            records name when they all agree, else the env's default ``CameraModel.realistic()``).
        compare_width: frames wider than this are scaled down once on loading.
        held_out: fraction of the frames held out for the reported gaps.
        fit_frames: at most this many fitting frames are used by the parameter search.
        max_steps: at most this many effects are added.
        candidates: effect names that may be added (default: every registered effect and every measured
            member, :mod:`~weather_gym.gap.measured`).
        top: candidates fully fitted per step (the best of the k-grid screening).
        alpha: family-wise significance level (Holm) of disagreements and of a step.
        min_effect: smallest standardised bias reported as a disagreement.
        bootstrap: bootstrap resamples of the image signals (perception uses 300).
        perception: run the detector (the report's perception level).
        detector: a detector spec (``"yolov8:model.onnx"``, a ``DetectorSpec``; default: the shipped
            detector; see ``weather_gym.perception.load_detector``).
        prune: after the loop, drop every added effect whose removal does not worsen the held-out
            gap significantly.
    """

    seed: int = 0
    mode: str = "auto"
    tracks: tuple[str, ...] | None = None
    sim_frames: int | None = None
    scene: str | None = None
    camera_model: CameraModel | None = None
    held_out: float = 0.5
    fit_frames: int = 32
    max_steps: int = 4
    candidates: tuple[str, ...] | None = None
    top: int = 2
    alpha: float = ALPHA
    min_effect: float = MIN_EFFECT
    bootstrap: int = 1000
    perception: bool = True
    detector: Any = None
    prune: bool = True
    compare_width: int | None = COMPARE_WIDTH
    progress: bool = False

    def __post_init__(self) -> None:
        if not 0.0 < self.held_out < 1.0:
            raise InputError(f"held_out must be a fraction in (0, 1), got {self.held_out}")
        if self.mode not in MODES:
            raise InputError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.scene is not None and self.scene not in SCENES:
            raise InputError(f"scene must be one of {SCENES} (or None: from the records), got {self.scene!r}")
        if self.camera_model is not None and not isinstance(self.camera_model, CameraModel):
            raise InputError(f"camera_model must be a CameraModel (or None: from the records), "
                             f"got {type(self.camera_model).__name__}")
        if self.sim_frames is not None and self.sim_frames < MIN_FRAMES:
            raise InputError(f"sim_frames must be >= {MIN_FRAMES}, got {self.sim_frames}")
        if self.compare_width is not None and self.compare_width < 64:
            raise InputError(f"compare_width must be >= 64 pixels (or None), got {self.compare_width}")
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
            if name not in MEASURED:
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
        self.pruned: list[dict[str, Any]] = []
        self.flagged: list[dict[str, Any]] = []
        self.attempts: list[dict[str, Any]] = []
        cfg = self.config
        t0 = time.perf_counter()
        m = data.measured
        self.measured_signals = signal_table(m.images, data.signal_depths("measured"), data.signal_boxes("measured"),
                                             data.signal_masks("measured"))
        self.reference_signals = None
        if data.did:
            r = data.reference
            self.reference_signals = signal_table(r.images, data.signal_depths("reference"),
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
                         reference=None if ref_idx is None else self.reference_signals[ref_idx],
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
            self._fixed_matches[which] = self._match([frames.images[i] for i in idx], [frames.gts[i] for i in idx])
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
                comp.perception = _perception_summary(prow, st["sim"], st["measured"], st["sim_clean"],
                                                      st["reference"])
            else:
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

        t0 = time.perf_counter()
        names = names if names is not None else self.config.candidates
        cands = candidates(self.model, None if names is None else [n for n in names if n not in MEASURED])
        screened: list[FitResult] = []
        for c in tqdm(cands, desc="screen", unit="effect", disable=not self.config.progress, leave=False):
            screened.append(screen(self.fit_ev, self.model, c))
        g_now = self.fit_ev.gap(self.model)
        useful = sorted((r for r in screened if r.fit_gap < g_now), key=lambda r: (r.fit_gap, r.candidate.describe()))
        chosen = list(useful[:self.config.top])
        kinds = self._disagreeing_kinds()
        if kinds:  # the parametric effect of the strongest disagreeing kind is always fully fitted
            extra = next((r for r in useful if r.candidate.name in KIND_EFFECTS.get(kinds[0], ())), None)
            if extra is not None and extra not in chosen:
                chosen.append(extra)
        out = []
        for r in chosen:
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
        divided by the number of candidates fully fitted, the gap falls by at least PENALTY per
        parameter and by at least :data:`MIN_GAP_CUT` (a change smaller than a tenth of a
        scene-to-scene spread is not worth an effect, however certain it is). Returns the step record, or None (nothing added) unless ``force``.
        """
        cfg = self.config
        f: FitResult = found["fit"]
        before = self.compare()
        after = self.compare(found["model"])
        test = gap_test(self.held_ev.meter, before.signals, after.signals, b=cfg.bootstrap, seed=cfg.seed)
        n_tested = max(len(alternatives), 1)
        needed = 1.0 - PENALTY * f.n_params
        ev = evidence(before.rows, after.rows, f.effect.name)
        ok = (test["p_value"] < cfg.alpha / n_tested and test["gap_after"] <= needed * test["gap_before"]
              and test["gap_before"] - test["gap_after"] >= MIN_GAP_CUT)
        why = "added" if ok else "not significant"
        if ok and not (ev["fixed"] or ev["improved"]):
            ok, why = False, "fixes no significant disagreement"
        what = describe(f.effect)
        hit = bounds_hit(f.effect, f.extras)
        beyond = None
        if ok and hit and not force:
            if test["gap_after"] <= CLIP_EXPLAINS * test["gap_before"] and not self.data.confounded:
                # the family is right but needs more range than it has: name it, say where it clipped
                beyond = {"flag": BEYOND_RANGE, "clipped": hit}
                why = f"added; {BEYOND_RANGE} ({'; '.join(hit)})"
            else:
                self._say(f"best candidate {what}: held-out gap {test['gap_before']:.3f} -> {test['gap_after']:.3f}, "
                          f"but the fit ends on a bound ({'; '.join(hit)}): not added (flagged)")
                self.flagged.append({"candidate": f.candidate.describe(), "describe": what, "bounds": hit,
                                     "gap_before": test["gap_before"], "gap_after": test["gap_after"],
                                     "p_value": test["p_value"], "step": len(self.steps) + 1,
                                     "why": "a fit on the edge of the effect's range that explains less than half of "
                                            "the gap: the effect cannot reproduce the difference inside its range, so "
                                            "the difference is probably something else (another effect, or the camera "
                                            "and scene rather than weather)"})
                self._attempt(f, test, f"fit on a bound ({'; '.join(hit)})")
                return None
        self._say(f"best candidate {what}: held-out gap {test['gap_before']:.3f} -> {test['gap_after']:.3f} "
                  f"(p = {test['p_value']:.4f}, {why})")
        if not ok and not force:
            if why == "not significant":
                why = (f"not significant (p = {test['p_value']:.2g})" if test["p_value"] >= cfg.alpha / n_tested
                       else f"cut too small ({test['gap_before'] - test['gap_after']:.2g} spreads)")
            self._attempt(f, test, why)
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
            "beyond_range": beyond,
            "measured": found.get("measured"),
        }
        self.model = found["model"]
        self.steps.append(step)
        self.history.append((f"+ {f.effect.name}", list(self.model)))
        return step

    def _disagreeing_kinds(self) -> list[str]:
        """Signal families that disagree significantly now, strongest first."""
        fam = {n: s.family for n, s in zip(SIGNAL_NAMES, SIGNALS)}
        return list(dict.fromkeys(fam[n] for n in self.compare(perception=False).significant))

    def rank(self, found: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """Candidates best first, by the evidence each family leaves, then by penalised held-out gap: an
        effect whose fingerprint (:data:`REQUIRES`: ``dim`` changes the brightness) does not disagree
        goes behind those whose does (noise without a brightness change is ``noise``, not
        ``dim``); a global tone change goes behind a radial one when the fall-off to the corners
        disagrees and a radial candidate comes within :data:`EVIDENCE_MARGIN` of it."""
        kinds = set(self._disagreeing_kinds())
        seen = kinds | set(self.compare(perception=False).significant)

        def evidenced(e: dict[str, Any]) -> bool:
            need = REQUIRES.get(e["fit"].effect.name, ())
            return not need or any(x in seen for x in need)

        best_radial = min((e["penalized"] for e in found if e["fit"].effect.name in KIND_EFFECTS["vignette"]
                           and evidenced(e)), default=math.inf)

        def demoted(e: dict[str, Any]) -> bool:
            return (e["fit"].effect.name in GLOBAL_TONE and "vignette" in kinds
                    and best_radial <= EVIDENCE_MARGIN * e["penalized"])

        return sorted(found, key=lambda e: (not evidenced(e), demoted(e), e["penalized"], e["fit"].candidate.describe()))

    def measure(self, found: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """Measured members (:mod:`~weather_gym.gap.measured`) of the kinds whose signals disagree and
        whose parametric effects fall short: none of them among the fully fitted candidates, or its fit
        clipped by its range, or it leaves more than half of the gap. Each is measured on the fitting
        frames (the model's output before its place in the chain against the measured frames), its k
        refined, and returned in :meth:`diagnose`'s format with ``measured``: its kind, the closest
        parametric effect and the residual shape."""
        t0 = time.perf_counter()
        sig = self.compare(perception=False).significant
        fam = {n: s.family for n, s in zip(SIGNAL_NAMES, SIGNALS)}
        kinds = {fam[n] for n in sig}
        present = {e.name for e in self.model}
        g_fit = self.fit_ev.gap(self.model)
        g_held = self.held_ev.gap(self.model)
        sim_idx, meas_idx = self._fit_idx
        d = self.data
        out = []
        for name, kind in KIND.items():
            if name in present or not set(MEASURED_KINDS.get(name, (kind,))) & kinds or (self.config.candidates is not None
                                                        and name not in self.config.candidates):
                continue
            partners = [f for f in found if f["fit"].effect.name in PARTNERS[name]]
            best = min(partners, key=lambda f: f["held_gap"]) if partners else None
            if best is not None and not bounds_hit(best["fit"].effect, best["fit"].extras) \
                    and best["held_gap"] <= 0.5 * g_held:
                continue  # the parametric effect does the job
            pos = insert_position(self.model, name)
            prefix = self.fit_ev.prefix(self.model[:pos])
            sim_masks = d.signal_masks("sim")
            member = estimate(name, prefix, [d.measured.images[i] for i in meas_idx],
                              sim_masks=[sim_masks[i] for i in sim_idx],
                              meas_masks=[d.measured.masks[i] for i in meas_idx], paired=d.paired)
            if member.is_identity():
                continue
            n0 = self.fit_ev.n_evals

            def obj(k: float, member=member, pos=pos) -> float:
                return self.fit_ev.gap(self.model[:pos] + [member.with_params(k=round(k, 3))] + self.model[pos:],
                                       split=pos)

            k, g = _brent(obj, 0.2, 1.0, maxiter=8)
            if obj(1.0) <= g:
                k, g = 1.0, obj(1.0)
            member = member.with_params(k=round(k, 3))
            model = self.model[:pos] + [member] + self.model[pos:]
            held = self.held_ev.gap(model)
            closest = None if best is None else {"describe": describe(best["fit"].effect), "held_gap": best["held_gap"],
                                                 "clipped": bounds_hit(best["fit"].effect, best["fit"].extras)}
            screened = [c for c in (found[0]["screened"] if found else [])
                        if c["candidate"].split("(")[0] in PARTNERS[name]]
            if closest is None and screened:  # only screened on the k grid: its best point there
                c = min(screened, key=lambda c: c["fit_gap"])
                closest = {"describe": f"{c['candidate']} at k = {c['k']:.2f} (k grid)", "held_gap": None,
                           "fit_gap": c["fit_gap"], "clipped": []}
            info = {"kind": kind, "closest_parametric": closest, "shape": shape_text(member),
                    "why": ("no parametric effect of this kind was among the best fits" if best is None else
                            f"{closest['describe']} " + (f"is clipped by its range ({'; '.join(closest['clipped'])})"
                                                         if closest["clipped"] else
                                                         f"leaves {best['held_gap']:.2f} of {g_held:.2f}"))}
            self._say(f"measured {kind} member {describe(member)}: held-out gap {g_held:.3f} -> {held:.3f} "
                      f"({info['why']})")
            f = FitResult(Candidate(name), member, pos, g, MEASURED_PARAMS, [], self.fit_ev.n_evals - n0, [])
            out.append({"fit": f, "model": model, "held_gap": held, "fit_gap_before": g_fit,
                        "penalized": held * (1.0 + PENALTY * MEASURED_PARAMS), "measured": info,
                        "screened": found[0]["screened"] if found else []})
        self.timings["measure_s"] = self.timings.get("measure_s", 0.0) + time.perf_counter() - t0
        return out

    def _attempt(self, f: FitResult, test: dict[str, Any], why: str) -> None:
        """Record a candidate that was fitted but not added, and what stopped it (for the verdict)."""
        self.attempts.append({"step": len(self.steps) + 1, "candidate": f.candidate.describe(),
                              "name": f.effect.name, "describe": describe(f.effect), "gap_before": test["gap_before"],
                              "gap_after": test["gap_after"], "p_value": test["p_value"], "why": why})

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

    # ------------------------------------------------------------------ domain
    def domain(self) -> dict[str, Any] | None:
        """Domain differences (see :mod:`~weather_gym.gap.domain`): the measured clear reference against
        clean simulator frames (did mode), or the measured frames against them when the comparison is
        confounded; None in the other modes (same camera, or the simulator's own frames)."""

        d, cfg = self.data, self.config
        if d.did:
            base, sig, label, which = d.reference, self.reference_signals, "measured clear reference", "reference"
        elif d.confounded:
            base, sig, label, which = d.measured, self.measured_signals, "measured frames", "measured"
        else:
            return None
        sim_masks = d.signal_masks("sim")
        sim_sig = signal_table(d.sim.images, d.signal_depths("sim"), d.signal_boxes("sim"), sim_masks)
        meter = GapMeter(sig, scale=signal_scale(sig), weights=self.weights, paired=False)
        rows = compare_signals(meter, sim_sig, b=cfg.bootstrap, seed=cfg.seed, alpha=cfg.alpha,
                               min_effect=cfg.min_effect)
        extra = []
        cl = compare_clutter([clutter(im, m) for im, m in zip(d.sim.images, sim_masks)],
                             [clutter(im, m) for im, m in zip(base.images, d.signal_masks(which))],
                             seed=cfg.seed, alpha=cfg.alpha)
        if cl is not None:
            extra.append(cl)
        ego = ego_vehicle(base.images, base.masks) if base.real else None
        if ego is not None:
            extra.append(ego)
        out = {"compared": f"clean simulator frames against the {label}", "differences": name_differences(rows, extra),
               "rows": [r for r in rows if r["significant"]]}
        if cfg.perception:
            sim_gts = [d.sim.gts[i] for i in d.sim_held]
            sim_m = self._fixed_matches.get("sim_clean") or self._match(self.held_ev.frames([]), sim_gts)
            out["perception"] = {"map50_sim": perception_stats(sim_m)["map50"],
                                 f"map50_{which}": perception_stats(self._fixed(which))["map50"]}
        return out

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

    def perception_warning(self, first: Comparison) -> str | None:
        """A sentence when the detector scores too low on the measured clear frames for the perception
        gap to mean anything (mAP@0.5 below :data:`PERCEPTION_MIN_MAP`), else None."""
        p = first.perception
        if p is None:
            return None
        d = self.data
        if d.did:
            value, what = p.get("map50_reference"), "the measured clear reference"
        elif d.mode == "same-camera":
            value, what = self.compare([]).perception["map50_sim"], "the measured clear reference"
        else:
            value, what = p.get("map50_measured"), "the measured frames"
        if value is None or not math.isfinite(value) or value >= PERCEPTION_MIN_MAP:
            return None
        return (f"the detector ({self.detector.name}) scores mAP@0.5 {value:.3f} on {what}: too low for the "
                "perception gap to mean anything (a detector that does not find the cones in clear frames cannot "
                "show what weather does to them); judge the run by the image signals, or use a detector that works "
                "on this camera (--detector yolov8:PATH)")

    def unexplained(self, last: Comparison) -> dict[str, Any] | None:
        """What the final model leaves unexplained on the held-out frames: None when no image signal
        disagrees significantly, else the gap, the signals that carry it (strongest first, with their
        families) and the closest candidates with what stopped each."""
        sig = last.significant
        if not sig:
            return None
        fam = {n: s.family for n, s in zip(SIGNAL_NAMES, SIGNALS)}
        rows = {r["signal"]: r for r in last.rows}
        in_model = {e.name for e in self.model}
        tried = [a for a in self.attempts if a["name"] not in in_model]
        last_step = max((a["step"] for a in tried), default=0)  # the last round: gaps against the final model
        close = sorted((a for a in tried if a["step"] == last_step), key=lambda a: a["gap_after"])
        seen, closest = set(), []
        for a in close:
            if a["name"] not in seen:
                seen.add(a["name"])
                closest.append(a)
        return {"gap": last.gap, "signals": [{"signal": n, "family": fam.get(n), "standardized": rows[n].get("standardized")}
                                            for n in sig],
                "families": list(dict.fromkeys(fam.get(n) for n in sig)), "closest": closest[:3]}

    def verdict(self, missing: Sequence[str], last: Comparison) -> str:
        """One sentence that follows the numbers: what was added (and where a family ran out of range),
        and, while the held-out gap is significantly above zero, how much is unexplained, which signals
        carry it and the closest candidates with what stopped each."""
        parts = []
        if missing:
            beyond = {st["added"]["name"]: st["beyond_range"] for st in self.steps if st.get("beyond_range")}
            parts.append("missing weather: " + ", ".join(
                f"{n} ({BEYOND_RANGE}: {'; '.join(beyond[n]['clipped'])})" if n in beyond else n for n in missing))
        u = self.unexplained(last)
        if u is None:
            if not missing:
                return "no missing weather: the model explains the measured frames"
            return parts[0]
        sigs = ", ".join(s["signal"] for s in u["signals"][:4])
        text = (f"{'still ' if missing else ''}unexplained: held-out gap {u['gap']:.2f} spreads, significantly above "
                f"zero ({len(u['signals'])} signals disagree, strongest {sigs}: {', '.join(u['families'][:3])})")
        if u["closest"]:
            text += "; closest candidates: " + ", ".join(
                f"{a['describe']} ({a['gap_before']:.2f} -> {a['gap_after']:.2f}, stopped: {a['why']})"
                for a in u["closest"])
            same = [a for a in u["closest"] if EFFECT_FAMILY.get(a["name"]) in u["families"][:2]]
            if same:
                text += (f"; the model lacks more of the kind these signals measure ({u['families'][0]}): widen or "
                         f"reshape {same[0]['name']}, or look for a cause outside the weather model")
            else:
                text += (f"; no candidate of the kind these signals measure ({u['families'][0]}) lowered it: the "
                         "model lacks such an effect, or the cause is outside the weather model (scene, camera)")
        else:
            text += (f"; no candidate effect lowers it: the model lacks an effect of the kind these signals measure "
                     f"({u['families'][0]}), or the cause is outside the weather model")
        parts.append(text)
        return "; ".join(parts)

    def report(self, first: Comparison | None = None, last: Comparison | None = None) -> dict[str, Any]:
        """The report dict (``report.json``'s content, without file paths)."""
        first = first or self.compare(self.input_model)
        last = last or self.compare()
        d = self.data
        missing = [s["added"]["name"] for s in self.steps if s["added"]["name"] not in {p["name"] for p in self.pruned}]
        if d.confounded:
            verdict = ("confounded: the measured frames differ from the clean simulator, but without a clear "
                       "reference of the same camera the difference cannot be told apart from the camera and scene; "
                       "nothing was fitted as weather")
        else:
            verdict = self.verdict(missing, last)
        if self.flagged:
            verdict += f"; flagged (fit on a bound, not added): {', '.join(f['candidate'] for f in self.flagged)}"
        return {
            "version": REPORT_VERSION,
            "mode": d.mode,
            "mode_reason": d.mode_reason,
            "verdict": verdict,
            "confounded": d.confounded,
            "confounded_reason": d.confounded_reason or None,
            "perception_warning": self.perception_warning(first),
            "domain": self.domain(),
            "flagged": self.flagged,
            "beyond_range": [{"name": st["added"]["name"], **st["beyond_range"]} for st in self.steps
                             if st.get("beyond_range") and st["added"]["name"] in missing],
            "unexplained": self.unexplained(last),
            "attempts": self.attempts,
            "pruned": self.pruned,
            "notes": list(d.notes),
            "frames": {"measured": len(d.measured), "simulated": len(d.sim),
                       "reference": None if d.reference is None else len(d.reference), "fit": int(len(d.fit)),
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
            "missing_effects": missing,
            "model_in": model_tables(self.input_model),
            "model_effects": model_tables(self.model),
            "signals": [{"name": n, "scale": float(s)} for n, s in zip(SIGNAL_NAMES, self.scale)],
            "settings": {f.name: _setting(getattr(self.config, f.name)) for f in fields(self.config)
                         if f.name != "progress"},
            "log": list(self.log),
        }


def _perception_summary(rows: list[dict[str, Any]], sim: dict[str, float], meas: dict[str, float],
                        sim_clean: dict[str, float] | None = None,
                        reference: dict[str, float] | None = None) -> dict[str, Any]:
    """The perception level of a comparison; in difference-in-differences mode (``sim_clean`` and
    ``reference`` given) ``diff`` is ``(sim - sim_clean) - (measured - reference)`` of mAP@0.5."""
    by = {r["signal"]: r for r in rows}
    m = by["map50"]
    extra = {}
    if sim_clean is not None and reference is not None:
        extra = {"map50_sim_clean": sim_clean["map50"], "map50_reference": reference["map50"],
                 "change_sim": sim["map50"] - sim_clean["map50"], "change_measured": meas["map50"] - reference["map50"]}
    return {
        **extra,
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


def _setting(v: Any) -> Any:
    """A GapConfig value for the report: tuples as lists, a detector spec as its text."""
    if isinstance(v, tuple):
        return list(v)
    if v is None or isinstance(v, bool | int | float | str):
        return v
    return str(v)


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
            config: GapConfig | None = None, *, reference: str | os.PathLike | None = None,
            cache_dir: str | os.PathLike | None = None, overwrite: bool = False, plots: bool = True) -> dict[str, Any]:
    """Run the whole workflow and write ``report.json``, ``model.toml``, ``report.md`` and plots to ``out``.

    ``model`` None is the clean simulator. ``reference``: measured clear frames of the same camera
    (same-camera mode, or ``config.mode="did"``). The clean renders are cached in ``cache_dir``
    (default ``out/cache``); an existing report in ``out`` is never overwritten unless ``overwrite``.
    Returns the report dict as written to ``report.json``.
    """

    config = config or GapConfig()
    out = Path(out)
    t_start = time.perf_counter()

    for name in ("report.json", "model.toml", "report.md", *(PLOT_NAMES if plots else ())):
        check_output(out / name, overwrite=overwrite)
    effects = read_model(model) if model is not None else []
    out.mkdir(parents=True, exist_ok=True)
    with exclusive(out, message=f"another gap run is writing {out}; wait for it to finish or choose another --out"):
        return _run_gap_locked(measured, model, out, config, effects, reference=reference, cache_dir=cache_dir,
                               overwrite=overwrite, plots=plots, t_start=t_start)


def _run_gap_locked(measured, model, out: Path, config: GapConfig, effects: list, *, reference, cache_dir,
                    overwrite: bool, plots: bool, t_start: float) -> dict[str, Any]:
    """:func:`run_gap` once its outputs are checked and ``out`` is locked for this run."""
    cache = Path(cache_dir) if cache_dir is not None else out / "cache"
    t0 = time.perf_counter()
    data = simulate(measured, cache_dir=cache, mode=config.mode, reference=reference,
                    tracks=list(config.tracks) if config.tracks else None, sim_frames=config.sim_frames,
                    scene=config.scene, held_out=config.held_out, seed=config.seed, progress=config.progress,
                    compare_width=config.compare_width, camera_model=config.camera_model)
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
    report["reference"] = None if reference is None else str(reference)
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
