"""The gap workflow on hidden effects drawn from wide families: rates per family and setting.

The generator (``weather_gym/lab/gap/validation/hidden.py``) is independent of the weather library;
scenes, splits and the rates with Wilson 95 % intervals are in ``weather_gym/lab/gap/validation/runner.py``.

Usage::

    python benchmarks/gap_validation.py --split held-out --out scratch/gap_validation/held-out
    python benchmarks/gap_validation.py --small --split dev        # 1 case per family, paired only

Prints one line per case and the Markdown table, and writes ``OUT/results.jsonl`` (resumable: cases
already there are not run again), ``OUT/summary.json`` and ``OUT/table.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from weather_gym.lab.gap.validation import (
    FAMILIES,
    SETTINGS,
    SPLITS,
    CaseResult,
    run_validation,
    summarize,
    table,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=SPLITS, default="dev")
    ap.add_argument("--out", default=None, help="default: scratch/gap_validation/SPLIT")
    ap.add_argument("--settings", default=",".join(SETTINGS))
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--per-family", type=int, default=4, help="cases per family and setting")
    ap.add_argument("--frames", type=int, default=80, help="simulated frames per recording (the issue's recordings: 80)")
    ap.add_argument("--width", type=int, default=224, help="simulated frame width (16:9)")
    ap.add_argument("--small", action="store_true", help="one case per family, paired only, 16 frames at 192")
    ap.add_argument("--table-only", action="store_true", help="only the table of every case in OUT/results.jsonl")
    a = ap.parse_args()
    if a.small:
        a.per_family, a.frames, a.width, a.settings = 1, 16, 192, "paired"
    out = Path(a.out or f"scratch/gap_validation/{a.split}")
    shared = Path(os.environ.get("WEATHER_GYM_SHARED", "/work/shared"))
    if a.table_only:
        results = [CaseResult(**json.loads(line)) for line in (out / "results.jsonl").read_text().splitlines()]
    else:
        results = run_validation(out, split=a.split, settings=a.settings.split(","), families=a.families.split(","),
                                 per_family=a.per_family, frames=a.frames, width=a.width, shared=shared,
                                 log=lambda s: print(s, flush=True))
    rows = summarize(results)
    text = table(rows)
    print(text)
    (out / "table.md").write_text(text + "\n")
    (out / "summary.json").write_text(json.dumps({"args": vars(a), "rows": rows}, indent=1))


if __name__ == "__main__":
    sys.exit(main())
