"""Name what a model change fixed: the evidence of a step, from two held-out comparisons.

A signal is **fixed** when it disagreed significantly before the change and no longer does, and
**improved** when its standardised bias at least halved; a signal that did not disagree before
but does after is **worsened**. The summary sentence names the strongest ones.

Example:
    >>> from weather_gym.lab.gap.diagnose import evidence
    >>> before = [{"signal": "sharp_fine", "standardized": -12.0, "significant": True}]
    >>> after = [{"signal": "sharp_fine", "standardized": -0.2, "significant": False}]
    >>> evidence(before, after, "blur")["fixed"]
    ['sharp_fine']
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

__all__ = ["evidence", "significant_signals"]


def significant_signals(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Names of the rows flagged significant, strongest effect first."""
    sig = [r for r in rows if r.get("significant")]
    sig.sort(key=lambda r: -abs(r.get("standardized", r.get("effect_size", 0.0)) or 0.0))
    return [r["signal"] for r in sig]


def _b(r: dict[str, Any]) -> float:
    v = r.get("standardized", math.nan)
    return abs(v) if v is not None and math.isfinite(v) else math.nan


def evidence(before: Sequence[dict[str, Any]], after: Sequence[dict[str, Any]], what: str) -> dict[str, Any]:
    """Per-signal change between two comparisons (image rows) and a one-line summary."""
    after_by = {r["signal"]: r for r in after}
    signals, fixed, improved, worsened = [], [], [], []
    for r0 in before:
        r1 = after_by.get(r0["signal"])
        if r1 is None:
            continue
        b0, b1 = _b(r0), _b(r1)
        s0, s1 = bool(r0.get("significant")), bool(r1.get("significant"))
        signals.append({"signal": r0["signal"], "before": r0.get("standardized"), "after": r1.get("standardized"),
                        "significant_before": s0, "significant_after": s1})
        if s0 and not s1:
            fixed.append((b0, r0["signal"]))
        elif math.isfinite(b0) and math.isfinite(b1) and s0 and b1 <= 0.5 * b0:
            improved.append((b0, r0["signal"]))
        if s1 and not s0:
            worsened.append((b1, r0["signal"]))
    order = sorted(range(len(signals)), key=lambda i: -(_abs_drop(signals[i])))
    signals = [signals[i] for i in order]
    fixed_names = [n for _, n in sorted(fixed, key=lambda t: -t[0])]
    improved_names = [n for _, n in sorted(improved, key=lambda t: -t[0])]
    worsened_names = [n for _, n in sorted(worsened, key=lambda t: -t[0])]
    parts = []
    if fixed_names:
        parts.append(f"fixes {_list(fixed_names, signals)}")
    if improved_names:
        parts.append(f"improves {_list(improved_names, signals)}")
    if worsened_names:
        parts.append(f"but now disagrees on {', '.join(worsened_names[:4])}")
    summary = f"{what} " + ("; ".join(parts) if parts else "changes no significant signal")
    return {"summary": summary, "fixed": fixed_names, "improved": improved_names, "worsened": worsened_names,
            "signals": signals}


def _abs_drop(s: dict[str, Any]) -> float:
    b0 = s["before"] if s["before"] is not None and math.isfinite(s["before"]) else 0.0
    b1 = s["after"] if s["after"] is not None and math.isfinite(s["after"]) else 0.0
    return abs(b0) - abs(b1)


def _list(names: list[str], signals: list[dict[str, Any]], limit: int = 5) -> str:
    by = {s["signal"]: s for s in signals}
    items = [f"{n} ({by[n]['before']:+.1f} -> {by[n]['after']:+.1f})" for n in names[:limit]]
    more = f" and {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(items) + more
