"""Addresses of symbols in a loaded shared object, from its ELF symbol table (Linux, 64-bit).

For settings a compiled library keeps in a global and offers no call for (PyBullet's EGL plugin
draws its shadow map whatever ``getCameraImage(shadow=0)`` asks; :mod:`weather_gym.sim.egl.shadow_map`).

Example:
    >>> from weather_gym.sim.egl.elf_symbols import elf_symbol
    >>> elf_symbol(__file__, "anything") is None  # not an ELF file
    True
"""

from __future__ import annotations

import os
import struct
import sys

_SHT_SYMTAB = 2


def elf_symbol(path: str | os.PathLike, name: str) -> tuple[int, int] | None:
    """``(value, size)`` of ``name`` in the file's static symbol table (``.symtab``), or None when the
    file is not a 64-bit little-endian ELF file, has no symbol table (a stripped build) or no such symbol.
    ``value`` is the symbol's address relative to where the object is loaded."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x7fELF" or len(data) < 64 or data[4] != 2 or data[5] != 1:
        return None
    (shoff,) = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)
    if shoff == 0 or shoff + shnum * shentsize > len(data):
        return None
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]
    wanted = name.encode() + b"\0"
    for _name, kind, _flags, _addr, offset, size, link, _info, _align, entsize in sections:
        if kind != _SHT_SYMTAB or entsize == 0 or link >= shnum:
            continue
        strings = sections[link][4]
        for j in range(size // entsize):
            st_name, _, _, _, value, st_size = struct.unpack_from("<IBBHQQ", data, offset + j * entsize)
            start = strings + st_name
            if data.startswith(wanted, start):
                return value, st_size
    return None


def load_address(path: str | os.PathLike) -> int | None:
    """Where the shared object at ``path`` is loaded in this process (the start of its mapping at file
    offset 0), or None when it is not loaded (or ``/proc/self/maps`` cannot be read)."""
    real = os.path.realpath(path)
    try:
        with open("/proc/self/maps") as f:
            for line in f:
                parts = line.split(maxsplit=5)
                if len(parts) == 6 and int(parts[2], 16) == 0 and os.path.realpath(parts[5].strip()) == real:
                    return int(parts[0].split("-")[0], 16)
    except OSError:
        return None
    return None


class SymbolUnavailable(LookupError):
    """Why a symbol of a loaded shared object cannot be had; ``lasting`` when asking again in this
    process will not help (a stripped build), False when it may (the object is not loaded yet)."""

    def __init__(self, reason: str, *, lasting: bool) -> None:
        super().__init__(reason)
        self.lasting = lasting


def loaded_symbol(path: str | None, name: str, what: str) -> tuple[str, int, int]:
    """``(path, address, size)`` of ``name`` in the shared object at ``path`` as loaded in this process
    (``what`` names the object in messages). Raises :class:`SymbolUnavailable` saying why not."""
    if not sys.platform.startswith("linux") or sys.maxsize < 2**32:
        raise SymbolUnavailable(f"{name} of {what} is found in 64-bit Linux builds only", lasting=True)
    base = load_address(path) if path else None
    if path is None or base is None:
        raise SymbolUnavailable(f"{what} is not loaded in this process", lasting=False)
    symbol = elf_symbol(path, name)
    if symbol is None:
        raise SymbolUnavailable(f"{path} has no symbol table entry {name!r} (a stripped or other build of {what})",
                                lasting=True)
    return path, base + symbol[0], symbol[1]
