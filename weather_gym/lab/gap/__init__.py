"""The sim-versus-measured gap workflow: find where they disagree, name the missing effect, add it.

The command is ``weather-gym gap MEASURED_DIR --model MODEL.toml --out OUT_DIR`` (:func:`run_gap`);
the same steps one at a time, for a notebook (see ``docs/gap.md``)::

    from weather_gym.lab.gap import GapConfig, GapSession, read_model, simulate

    data = simulate("data/measured", cache_dir="out/cache")   # clean renders of the same views
    s = GapSession(data, read_model("model.toml"), GapConfig(seed=0))
    s.compare().disagreements()   # perception and image signals, with bootstrap uncertainty
    s.refit()                     # re-fit the k (and parameters) of the effects already in the model
    found = s.diagnose()          # fit every candidate effect, best first
    s.add(found[0])               # add it if it shrinks the held-out gap significantly
    report = s.run()              # or the whole loop

Modules: :mod:`.simulate` (paired / unpaired renders), :mod:`.signals` (image signals per frame),
:mod:`.perception` (detector matches, bootstrappable mAP), :mod:`.compare` (gaps, bootstrap tests),
:mod:`.fit` (parameter search), :mod:`.diagnose` (evidence), :mod:`.model` (model TOML files),
:mod:`.report` (Markdown, plots), :mod:`.synthetic` (measured data with a hidden effect),
:mod:`.workflow` (the session and the command).

Example:
    >>> from weather_gym.lab.gap import GapConfig
    >>> GapConfig(seed=3).max_steps
    4
"""

from __future__ import annotations

from weather_gym.core._lazy import lazy_exports

_LAZY = {
    "GapConfig": "weather_gym.lab.gap.workflow",
    "GapSession": "weather_gym.lab.gap.workflow",
    "Comparison": "weather_gym.lab.gap.workflow",
    "run_gap": "weather_gym.lab.gap.workflow",
    "simulate": "weather_gym.lab.gap.simulate",
    "GapData": "weather_gym.lab.gap.simulate",
    "split_indices": "weather_gym.lab.gap.simulate",
    "frame_signals": "weather_gym.lab.gap.signals",
    "signal_table": "weather_gym.lab.gap.signals",
    "SIGNALS": "weather_gym.lab.gap.signals",
    "compare_signals": "weather_gym.lab.gap.compare",
    "compare_perception": "weather_gym.lab.gap.compare",
    "gap_test": "weather_gym.lab.gap.compare",
    "candidates": "weather_gym.lab.gap.fit",
    "fit": "weather_gym.lab.gap.fit",
    "refit": "weather_gym.lab.gap.fit",
    "screen": "weather_gym.lab.gap.fit",
    "evidence": "weather_gym.lab.gap.diagnose",
    "read_model": "weather_gym.lab.gap.weather_model",
    "write_model": "weather_gym.lab.gap.weather_model",
    "apply_chain": "weather_gym.lab.gap.weather_model",
    "degrade_dataset": "weather_gym.lab.gap.synthetic",
    "MEASURED": "weather_gym.lab.gap.measured",
    "make_measured": "weather_gym.lab.gap.measured",
}

__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
