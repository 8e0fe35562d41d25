"""The sim-versus-measured gap workflow: compare, name the missing effect, add it, show the gap shrink.

:class:`GapSession` holds the measured frames, their clean simulated counterparts (from
:func:`~weather_gym.lab.gap.simulate.simulate`) and the current weather model, and runs one step at a
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

Selection is driven by the image-signal gap (:mod:`~weather_gym.lab.gap.compare`): it is sensitive
(per-frame differences in paired mode) and it tells effects apart; the detector's mAP is one
number that many different effects can move by the same amount, and it is noisy on a few hundred
frames. The perception gap (``|mAP_sim - mAP_measured|`` at IoU 0.5, per class, recall by range
and box size, score distributions) is reported first, before and after every step.

Example:
    >>> from weather_gym.lab.gap.workflow import GapConfig
    >>> GapConfig().held_out
    0.5
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.core._io import atomic_write_json, check_output, exclusive
from weather_gym.lab.gap.config import (
    BEYOND_RANGE,
    CLIP_EXPLAINS,
    EFFECT_FAMILY,
    EVIDENCE_MARGIN,
    GLOBAL_TONE,
    KIND_EFFECTS,
    MEASURED_KINDS,
    MIN_GAP_CUT,
    PERCEPTION_MIN_MAP,
    REPORT_VERSION,
    REQUIRES,
    Comparison,
    GapConfig,
)
from weather_gym.lab.gap.report import PLOT_NAMES, write_markdown, write_plots
from weather_gym.lab.gap.session import GapSession
from weather_gym.lab.gap.simulate import simulate
from weather_gym.lab.gap.weather_model import read_model, write_model

__all__ = ["GapConfig", "Comparison", "GapSession", "run_gap", "REPORT_VERSION", "BEYOND_RANGE", "CLIP_EXPLAINS",
           "EFFECT_FAMILY", "EVIDENCE_MARGIN", "GLOBAL_TONE", "KIND_EFFECTS", "MEASURED_KINDS", "MIN_GAP_CUT",
           "PERCEPTION_MIN_MAP", "REQUIRES"]


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
