"""One entry of PyBullet's EGL plugin's GL pointer table, pointed at a function of our own.

The plugin calls OpenGL through glad's table of function pointers (``glad_glViewport``, ...), found in
its symbol table (:func:`weather_gym.sim.egl.elf_symbols.loaded_symbol`). :class:`GLTableEntry` checks
that an entry holds the driver's function, points it at a ctypes function, and points it again where
the plugin reloaded its table (it does for every new EGL context). :func:`gl_function` gives the
driver's own functions to call from there. Used by :mod:`weather_gym.sim.egl.shadow_reuse` and
``benchmarks/egl_passes.py``.

Example:
    >>> from weather_gym.sim.egl.gl_table import GL_SCISSOR_TEST
    >>> hex(GL_SCISSOR_TEST)
    '0xc11'
"""

from __future__ import annotations

import ctypes
from functools import cache

from weather_gym.sim.egl.elf_symbols import loaded_symbol
from weather_gym.sim.renderer import _egl_plugin_path

GL_SCISSOR_TEST = 0x0C11
GL_DRAW_FRAMEBUFFER_BINDING = 0x8CA6
#: ctypes prototypes of the GL functions these hooks call or stand in for.
ONE_ENUM = ctypes.CFUNCTYPE(None, ctypes.c_uint)  # glClear, glEnable, glDisable
FOUR_INTS = ctypes.CFUNCTYPE(None, *[ctypes.c_int] * 4)  # glViewport, glScissor
GET_INTEGER = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.POINTER(ctypes.c_int))  # glGetIntegerv


@cache
def _proc_address(name: str) -> int:
    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    return egl.eglGetProcAddress(name.encode()) or 0


def gl_function(name: str, prototype):
    """The driver's GL function ``name`` (``eglGetProcAddress``) as a ctypes function of ``prototype``."""
    return prototype(_proc_address(name))


def draw_framebuffer() -> int:
    """The framebuffer bound for drawing in the current context (0: the window)."""
    bound = ctypes.c_int(0)
    _get_integer()(GL_DRAW_FRAMEBUFFER_BINDING, ctypes.byref(bound))
    return bound.value


@cache
def _get_integer():
    return gl_function("glGetIntegerv", GET_INTEGER)


class GLTableEntry:
    """The plugin's table entry ``glad_<name>``, pointed at ``function`` (a ctypes function of the GL
    function's prototype, kept alive here). Raises ``SymbolUnavailable`` (from
    :func:`~weather_gym.sim.egl.elf_symbols.loaded_symbol`) or ``LookupError`` when it cannot be had."""

    def __init__(self, name: str, function) -> None:
        path, slot, size = loaded_symbol(_egl_plugin_path(), f"glad_{name}", "PyBullet's EGL plugin")
        self.driver = _proc_address(name)  # the driver's function, which the entry holds as loaded
        self._slot = ctypes.c_uint64.from_address(slot)
        if size != 8 or not self.driver or self._slot.value != self.driver:
            raise LookupError(f"glad_{name} in {path} does not hold the driver's {name}")
        self._pinned = ctypes.CDLL(path)  # the plugin stays where the entry was found
        self._function = function  # kept alive as long as the table points at it
        self._address: int = ctypes.cast(function, ctypes.c_void_p).value  # type: ignore[assignment]  # a live function: not NULL
        self.repointed = 0  # times the entry was found reloaded and pointed again
        self._slot.value = self._address

    def ensure(self) -> bool:
        """Point the entry at the function again where the plugin reloaded its table; False when it
        holds something else than the driver's function or ours."""
        if self._slot.value == self._address:
            return True
        if self._slot.value != self.driver:
            return False
        self._slot.value = self._address
        self.repointed += 1
        return True

    def release(self) -> None:
        """Point the entry back at the driver's function (until the next :meth:`ensure`)."""
        self._slot.value = self.driver
