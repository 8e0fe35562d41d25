"""One name per idea across the commands (the CLI's and the benches'), with the old spellings kept
for one release.

:func:`alias` gives an option an old spelling that still works for one release: it is hidden from
``--help`` (which shows one name per idea) and prints one note saying what to write instead. The
names are listed in docs/cli.md, which ``tests/cli/test_vocabulary.py`` checks against the parsers.

Example:
    >>> import argparse
    >>> p = argparse.ArgumentParser()
    >>> _ = p.add_argument("--env-id", default="WeatherGym/ConeTrack-v0")
    >>> alias(p, "--env-id", "--env")
    >>> p.parse_args(["--env", "X"]).env_id   # prints a note on stderr
    'X'
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

_PLAIN = (argparse._StoreAction, argparse._AppendAction)
_FLAGS = (argparse._StoreTrueAction, argparse._StoreFalseAction)


def alias(parser: argparse.ArgumentParser, new: str, old: str, *, note: str | None = None) -> None:
    """Take ``old`` as a deprecated spelling of ``new`` (an option already added to ``parser``): the same
    destination, type and choices, hidden from the help, with a note on stderr when it is used."""
    action = parser._option_string_actions[new]
    kind = type(action)
    if not issubclass(kind, _PLAIN + _FLAGS):
        raise TypeError(f"alias: {new} is a {kind.__name__}; only store, append and flag options take an alias")

    class Deprecated(kind):  # type: ignore[valid-type, misc]  # the action class of the option it stands for
        def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                     option_string: str | None = None) -> None:
            print(f"note: {old} is deprecated and goes in the next release; use {new}"
                  + (f" ({note})" if note else ""), file=sys.stderr)
            super().__call__(parser, namespace, values, option_string)

    kwargs: dict[str, Any] = {"dest": action.dest, "help": argparse.SUPPRESS, "default": argparse.SUPPRESS}
    if issubclass(kind, _PLAIN):
        kwargs.update(nargs=action.nargs, type=action.type, choices=action.choices, metavar=action.metavar)
    parser.add_argument(old, action=Deprecated, **kwargs)


class OneDefaultFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's defaults-in-help, once per option: not where the help already says its default, not
    for a required option, nor for an option whose default is nothing (None, False, an empty list)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text or action.required or action.default in (None, False, [], argparse.SUPPRESS):
            return text
        return super()._get_help_string(action) or text
