"""Frames from PyBullet's EGL plugin without its shadow map (``SimConfig(shadows=False)``).

The plugin draws a 4096x4096 shadow map before every frame and shades the scene by it, whatever
``getCameraImage(shadow=0)`` asks: that argument reaches TinyRenderer only. On Mesa's llvmpipe the
pass costs about 15 ms a frame whatever the image size (``weather-gym bench sim --naive``). The
plugin offers no call to skip it; its switch is a global of the plugin's renderer (``useShadowMap``
in bullet3's ``GLInstancingRenderer``), found here from the plugin's symbol table.
:func:`shadow_map_off` clears it around one frame and sets it back, so every other frame of the
process is drawn as the plugin draws it.

Example:
    >>> from weather_gym.sim.egl.shadow_map import unavailable_reason
    >>> unavailable_reason() is None or isinstance(unavailable_reason(), str)
    True
"""

from __future__ import annotations

import contextlib
import ctypes
from collections.abc import Iterator

from weather_gym.sim.egl.elf_symbols import SymbolUnavailable, loaded_symbol
from weather_gym.sim.renderer import _egl_plugin_path

_SYMBOL = "useShadowMap"
_flag: ctypes.c_uint8 | None = None
_reason: str | None = None
_pinned: ctypes.CDLL | None = None  # our own reference to the plugin: it stays where the flag was found


def _find_flag(path: str, address: int, size: int) -> ctypes.c_uint8 | str:
    """The flag at ``address`` of the plugin loaded from ``path``, or a sentence saying why it is not it."""
    global _pinned
    flag = ctypes.c_uint8.from_address(address)
    if size != 1 or flag.value != 1:
        return f"{_SYMBOL} in {path} is not the set one-byte flag it should be (size {size}, value {flag.value})"
    _pinned = ctypes.CDLL(path)  # already loaded: the same object, one more reference
    return flag


def unavailable_reason() -> str | None:
    """None when the shadow map can be switched off in this process (the EGL plugin is loaded and
    its switch was found), else why not. Looked up once, at the first call after the plugin loaded."""
    global _flag, _reason
    if _flag is not None or _reason is not None:
        return _reason
    try:
        found = _find_flag(*loaded_symbol(_egl_plugin_path(), _SYMBOL, "PyBullet's EGL plugin"))
    except SymbolUnavailable as exc:
        if exc.lasting:
            _reason = str(exc)
        return str(exc)
    if isinstance(found, str):
        _reason = found
    else:
        _flag = found
    return _reason


@contextlib.contextmanager
def shadow_map_off() -> Iterator[None]:
    """EGL frames rendered inside have no shadow map; the plugin's own setting is put back after.

    Raises RuntimeError when the switch cannot be had (:func:`unavailable_reason`).
    """
    reason = unavailable_reason()
    if reason is not None:
        raise RuntimeError(f"cannot render EGL frames without PyBullet's shadow map: {reason}")
    assert _flag is not None
    _flag.value = 0
    try:
        yield
    finally:
        _flag.value = 1
