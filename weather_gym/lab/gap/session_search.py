"""The gap workflow's search for missing effects, a part of :class:`~weather_gym.lab.gap.session.GapSession`:
fit every candidate (:meth:`SearchSteps.diagnose`), measure the members of a kind whose parametric
effects fall short (:meth:`SearchSteps.measure`), rank them by the evidence each leaves
(:meth:`SearchSteps.rank`) and add the best when it shrinks the held-out gap significantly
(:meth:`SearchSteps.add`).

Example:
    >>> REQUIRES["noise"], KIND_EFFECTS["noise"]   # noise is named only when the noise signals disagree
    (('noise',), ('noise', 'noise_level'))
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

from tqdm import tqdm

from weather_gym.lab.gap.compare import GapMeter, gap_test
from weather_gym.lab.gap.config import (
    BEYOND_RANGE,
    CLIP_EXPLAINS,
    EVIDENCE_MARGIN,
    FURTHER_REQUIRES,
    GLOBAL_TONE,
    KIND_EFFECTS,
    MEASURED_KINDS,
    MIN_GAP_CUT,
    RADIAL_FIRST,
    REQUIRES,
    SECOND_SHARE,
)
from weather_gym.lab.gap.diagnose import evidence
from weather_gym.lab.gap.fit import (
    PENALTY,
    Candidate,
    FitResult,
    _brent,
    bounds_hit,
    candidates,
    fit,
    fit_summary,
    screen,
)
from weather_gym.lab.gap.measured import KIND, MEASURED, MEASURED_PARAMS, PARTNERS, estimate, shape_text
from weather_gym.lab.gap.session_host import SessionHost
from weather_gym.lab.gap.signals import SIGNAL_NAMES, SIGNALS
from weather_gym.lab.gap.weather_model import describe, insert_position


class SearchSteps(SessionHost):
    """Finding and adding missing effects; a part of :class:`~weather_gym.lab.gap.session.GapSession`
    (the session holds the data, the evaluators and the model these steps read and change)."""

    def diagnose(self, names: Sequence[str] | None = None) -> list[dict[str, Any]]:
        """Fit every candidate effect (k grid, then the best ``top`` fully); best first.

        Each entry: ``fit`` (a :class:`~weather_gym.lab.gap.fit.FitResult`), ``model`` (the current
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
        out: list[dict[str, Any]] = []
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
        floor = self.floor()
        share = (test["gap_before"] - test["gap_after"]) / max(test["gap_before"] - floor, 1e-9)
        need = FURTHER_REQUIRES.get(f.effect.name, ())
        if ok and self.steps and not force and (not found.get("evidenced", True) or need and not set(need) & (
                set(self._disagreeing_kinds()) | set(before.significant))):
            need = REQUIRES.get(f.effect.name, ()) + need
            ok, why = False, f"its fingerprint ({', '.join(need)}) does not disagree"
            self.candidates.append({"name": f.effect.name, "describe": describe(f.effect), "step": len(self.steps) + 1,
                                    "gap_before": test["gap_before"], "gap_after": test["gap_after"],
                                    "floor": floor, "share": share, "p_value": test["p_value"], "why": why})
        elif ok and self.steps and not force and (share < SECOND_SHARE
                                                  or test["gap_before"] - test["gap_after"] < floor):
            # a further effect must explain a real part of what is left above the floor on its own
            ok, why = False, (f"explains {max(share, 0.0):.0%} of the remaining gap above the floor "
                              f"({test['gap_before']:.2f} - {floor:.2f}): a further effect needs {SECOND_SHARE:.0%}, "
                              "and a cut of at least the floor (clear against clear)")
            self.candidates.append({"name": f.effect.name, "describe": describe(f.effect), "step": len(self.steps) + 1,
                                    "gap_before": test["gap_before"], "gap_after": test["gap_after"],
                                    "floor": floor, "share": share, "p_value": test["p_value"], "why": why})
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

    def _attempt(self, f: FitResult, test: dict[str, Any], why: str) -> None:
        """Record a candidate that was fitted but not added, and what stopped it (for the verdict)."""
        self.attempts.append({"step": len(self.steps) + 1, "candidate": f.candidate.describe(),
                              "name": f.effect.name, "describe": describe(f.effect), "gap_before": test["gap_before"],
                              "gap_after": test["gap_after"], "p_value": test["p_value"], "why": why})

    def _disagreeing_kinds(self) -> list[str]:
        """Signal families that disagree significantly now, strongest first."""
        fam = {n: s.family for n, s in zip(SIGNAL_NAMES, SIGNALS)}
        return list(dict.fromkeys(fam[n] for n in self.compare(perception=False).significant))

    def rank(self, found: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """Candidates best first, by the evidence each family leaves, then by penalised held-out gap: an
        effect whose fingerprint (:data:`REQUIRES`: ``dim`` changes the brightness) does not disagree
        goes behind those whose does (noise without a brightness change is ``noise``, not
        ``dim``); a global tone change or a bright-tile effect (:data:`RADIAL_FIRST`) goes behind a radial
        one when the fall-off to the corners disagrees and a radial candidate comes within
        :data:`EVIDENCE_MARGIN` of it; a global tone change goes behind ``fog`` when the far / near
        signals disagree beyond what a global curve explains and ``fog`` comes within that margin."""
        kinds = set(self._disagreeing_kinds())
        seen = kinds | set(self.compare(perception=False).significant)

        radial = "vignette" in kinds and not self._level_explains_position()
        hazy = "haze" in kinds and not self._level_explains_depth()
        level_from_noise = "noise" in kinds and self._noise_explains_level(found)

        def evidenced(e: dict[str, Any]) -> bool:
            name = e["fit"].effect.name
            if name in KIND_EFFECTS["vignette"] and not radial:
                return False  # the corners differ only as a function of their level: a global curve
            if name in ("dim", "exposure") and level_from_noise:
                return False  # noise keeps the mean level: the level change is the noise's clipping
            need = REQUIRES.get(name, ())
            return not need or any(x in seen for x in need)

        best_radial = min((e["penalized"] for e in found if e["fit"].effect.name in KIND_EFFECTS["vignette"]
                           and evidenced(e)), default=math.inf)

        best_haze = min((e["penalized"] for e in found if e["fit"].effect.name == "fog" and evidenced(e)),
                        default=math.inf)

        def demoted(e: dict[str, Any]) -> bool:
            name = e["fit"].effect.name
            return ((name in RADIAL_FIRST and radial and best_radial <= EVIDENCE_MARGIN * e["penalized"])
                    or (name in GLOBAL_TONE and hazy and best_haze <= EVIDENCE_MARGIN * e["penalized"]))

        for e in found:
            e["evidenced"] = evidenced(e)
        return sorted(found, key=lambda e: (not e["evidenced"], demoted(e), e["penalized"], e["fit"].candidate.describe()))

    def floor(self) -> float:
        """The gap a perfect model would still show on the held-out frames: 0 when the frames are
        compared one to one; unpaired, clear against clear: the gap between the fitting and the
        held-out simulated frames through the current model (two sets of different frames)."""
        if self.data.paired:
            return 0.0
        key = tuple((e.name, tuple(sorted(e.params().items()))) for e in self.model)
        cache = self._floors
        if key not in cache:
            meter = GapMeter(self.fit_ev.signals(self.model), scale=self.held_ev.meter.scale,
                             weights=self.held_ev.meter.weights, paired=False)
            cache[key] = meter.gap(self.held_ev.signals(self.model))
        return float(cache[key])

    def _after_level(self) -> list[str]:
        """The held-out signals that still disagree once a global curve (a measured ``tone_curve``
        member: every pixel mapped by its own level, wherever it is and however far) is applied."""
        key = tuple((e.name, tuple(sorted(e.params().items()))) for e in self.model)
        cache = self._after_level_cache
        if key not in cache:
            pos = insert_position(self.model, "tone_curve")
            d = self.data
            sim_idx, meas_idx = self._fit_idx
            sim_masks = d.signal_masks("sim")
            member = estimate("tone_curve", self.fit_ev.prefix(self.model[:pos]),
                              [d.measured.images[i] for i in meas_idx],
                              sim_masks=[sim_masks[i] for i in sim_idx],
                              meas_masks=[d.measured.masks[i] for i in meas_idx], paired=d.paired)
            cache[key] = list(self.compare(self.model[:pos] + [member] + self.model[pos:], perception=False).significant)
        return list(cache[key])

    def _level_explains_position(self) -> bool:
        """Position and level tested jointly: True when a global curve leaves no significant corner /
        centre disagreement on the held-out frames; a radial gain is named only when it does not."""
        return "vignette" not in self._after_level()

    def _level_explains_depth(self) -> bool:
        """Depth and level tested jointly: True when a global curve leaves the far / near signals
        (``haze_lift``, ``haze_contrast``) agreeing; a haze lifts far regions more than near ones at
        equal levels, so when they still disagree a haze goes before a global tone change."""
        return not {"haze_lift", "haze_contrast"} & set(self._after_level())

    def _noise_explains_level(self, found: Sequence[dict[str, Any]]) -> bool:
        """True when the best noise candidate explains a share of the held-out gap (at least
        :data:`SECOND_SHARE`) and alone leaves the mean level and the median agreeing: noise keeps the
        mean level, so a brightness change that goes with it is its clipping, not dimming. A noise
        candidate that explains little (a colour curve also moves the noise signals of bright regions)
        explains no level change."""
        noisy = [e for e in found if e["fit"].effect.name in KIND_EFFECTS["noise"]]
        if not noisy:
            return False
        best = min(noisy, key=lambda e: e["held_gap"])
        if best["held_gap"] > (1.0 - SECOND_SHARE) * self.held_ev.gap(self.model):
            return False
        sig = self.compare(best["model"], perception=False).significant
        return not ({"brightness", "tone_p50"} & set(sig))

    def measure(self, found: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """Measured members (:mod:`~weather_gym.lab.gap.measured`) of the kinds whose signals disagree and
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
            member = member.with_params(k=round(k, 3))  # type: ignore[assignment]  # with_params keeps the measured effect's class
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
                            f"{closest['describe']} " + (f"is clipped by its range ({'; '.join(closest['clipped'])})"  # type: ignore[index]  # best is set: so is closest
                                                         if closest["clipped"] else  # type: ignore[index]  # best is set: so is closest
                                                         f"leaves {best['held_gap']:.2f} of {g_held:.2f}"))}
            self._say(f"measured {kind} member {describe(member)}: held-out gap {g_held:.3f} -> {held:.3f} "
                      f"({info['why']})")
            f = FitResult(Candidate(name), member, pos, g, MEASURED_PARAMS, [], self.fit_ev.n_evals - n0, [])
            out.append({"fit": f, "model": model, "held_gap": held, "fit_gap_before": g_fit,
                        "penalized": held * (1.0 + PENALTY * MEASURED_PARAMS), "measured": info,
                        "screened": found[0]["screened"] if found else []})
        self.timings["measure_s"] = self.timings.get("measure_s", 0.0) + time.perf_counter() - t0
        return out
