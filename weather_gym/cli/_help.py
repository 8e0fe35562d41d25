"""Text from a registry (a mode's description, an agent's name) made safe for argparse's help.

argparse formats every help string with ``%`` (``%(default)s``), so a registry entry whose text holds a
``%`` (``"5 % range noise"``) would make ``--help`` fail with a ``TypeError``; registry text goes
through :func:`literal` before it joins a help string.

Example:
    >>> literal("cones with 5 % range noise")
    'cones with 5 %% range noise'
"""

from __future__ import annotations


def literal(text: str) -> str:
    """``text`` as argparse prints it unchanged (its ``%`` doubled)."""
    return text.replace("%", "%%")
