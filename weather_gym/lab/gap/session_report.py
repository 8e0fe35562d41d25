"""What a gap run reports, a part of :class:`~weather_gym.lab.gap.session.GapSession`: the held-out gap
after each change, the domain differences, what is left unexplained, the one-sentence verdict and the
report dict (``report.json``'s content).

Example:
    >>> rows = [{"signal": "map50", "difference": -0.12, "ci95": [-0.2, -0.04], "significant": True}]
    >>> scores = {"score_tp_mean": 0.8, "score_fp_mean": 0.4, "fp_per_frame": 0.2}
    >>> p = perception_summary(rows, {"map50": 0.61, **scores}, {"map50": 0.73, **scores})
    >>> p["abs_diff"], p["significant"]
    (0.12, True)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import fields
from typing import Any

from weather_gym.lab.gap.compare import GapMeter, compare_signals, signal_scale
from weather_gym.lab.gap.config import (
    BEYOND_RANGE,
    EFFECT_FAMILY,
    FLOOR_MARGIN,
    PERCEPTION_MIN_MAP,
    REPORT_VERSION,
    UNPAIRED_LIMITS,
    Comparison,
)
from weather_gym.lab.gap.domain import clutter, compare_clutter, ego_vehicle, name_differences
from weather_gym.lab.gap.perception import perception_stats
from weather_gym.lab.gap.session_host import SessionHost
from weather_gym.lab.gap.signals import SIGNAL_NAMES, SIGNALS, signal_table
from weather_gym.lab.gap.weather_model import model_tables


class ReportSteps(SessionHost):
    """The report of a run; a part of :class:`~weather_gym.lab.gap.session.GapSession` (it reads the
    session's steps, comparisons and log)."""

    # ------------------------------------------------------------------ domain
    def domain(self) -> dict[str, Any] | None:
        """Domain differences (see :mod:`~weather_gym.lab.gap.domain`): the measured clear reference against
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
        meter = GapMeter(sig, scale=signal_scale(sig), weights=self.weights, paired=False)  # type: ignore[arg-type]  # this branch's signals exist
        rows = compare_signals(meter, sim_sig, b=cfg.bootstrap, seed=cfg.seed, alpha=cfg.alpha,
                               min_effect=cfg.min_effect)
        extra = []
        cl = compare_clutter([clutter(im, m) for im, m in zip(d.sim.images, sim_masks)],
                             [clutter(im, m) for im, m in zip(base.images, d.signal_masks(which))],  # type: ignore[union-attr]  # this branch's frames exist
                             seed=cfg.seed, alpha=cfg.alpha)
        if cl is not None:
            extra.append(cl)
        ego = ego_vehicle(base.images, base.masks) if base.real else None  # type: ignore[union-attr]  # this branch's frames exist
        if ego is not None:
            extra.append(ego)
        out: dict[str, Any] = {"compared": f"clean simulator frames against the {label}", "differences": name_differences(rows, extra),
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
            value, what = self.compare([]).perception["map50_sim"], "the measured clear reference"  # type: ignore[index]  # a same-camera comparison with perception
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
        floor = self.floor()
        if not self.data.paired and u["gap"] <= FLOOR_MARGIN * floor:
            parts.append(f"{'the rest' if missing else 'nothing'} is beyond the unpaired floor: held-out gap "
                         f"{u['gap']:.2f} spreads against {floor:.2f} between two sets of clean simulated frames "
                         "(clear against clear); without poses what is left cannot be told from scene differences "
                         "(see unpaired_limits)")
            return "; ".join(parts) if missing else "no missing weather found without poses; " + parts[0]
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
            "candidates": self.candidates,
            "floor": self.floor(),
            "unpaired_limits": None if d.paired else [{"family": k, "why": v} for k, v in UNPAIRED_LIMITS.items()],
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




def perception_summary(rows: list[dict[str, Any]], sim: dict[str, float], meas: dict[str, float],
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
