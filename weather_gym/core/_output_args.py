"""The one overwrite option of every command that writes files: ``--overwrite`` (the CLI and the bench commands).

Without it an existing output is never replaced (``error: output ... already exists; pass
--overwrite ...``, exit status 2). ``--force``, the name some commands used before, is kept as a
hidden alias that prints a deprecation warning.

Example:
    >>> import argparse
    >>> parser = argparse.ArgumentParser()
    >>> add_overwrite_arg(parser)
    >>> parser.parse_args([]).overwrite, parser.parse_args(["--overwrite"]).overwrite
    (False, True)
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any


class _DeprecatedForce(argparse.Action):
    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        print(f"warning: {option_string} is deprecated; use --overwrite", file=sys.stderr)
        setattr(namespace, self.dest, True)


def add_overwrite_arg(p: argparse.ArgumentParser | argparse._ArgumentGroup, help: str = "replace existing output files (an input is never written to)") -> None:
    """Add ``--overwrite`` (and the hidden, deprecated ``--force``) to the parser or group ``p``."""
    p.add_argument("--overwrite", action="store_true", default=False, help=help)
    p.add_argument("--force", dest="overwrite", action=_DeprecatedForce, help=argparse.SUPPRESS)
