"""Markdown tables for the reports (tabulate's GitHub format).

Example:
    >>> print("\\n".join(markdown_table(["effect", "k"], [["dim", "0.5"]])))
    | effect   | k   |
    |----------|-----|
    | dim      | 0.5 |
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from tabulate import tabulate

__all__ = ["markdown_table"]


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> list[str]:
    """``rows`` under ``header`` as the lines of a Markdown table; each cell printed as ``str(cell)``
    (no number parsing, so a formatted number stays as formatted)."""
    return str(tabulate([[str(c) for c in r] for r in rows], headers=[str(h) for h in header], tablefmt="github",
                    disable_numparse=True)).splitlines()
