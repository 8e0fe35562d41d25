"""Symbols of a loaded shared object from its ELF symbol table."""

from __future__ import annotations

import pybullet
import pytest

from weather_gym.sim import renderer
from weather_gym.sim.egl.elf_symbols import SymbolUnavailable, elf_symbol, load_address, loaded_symbol
from weather_gym.sim.renderer import _egl_plugin_path


def test_files_that_are_not_elf_have_no_symbols(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("not a shared object")
    assert elf_symbol(text, "useShadowMap") is None
    short = tmp_path / "short.so"
    short.write_bytes(b"\x7fELF\x02\x01")  # an ELF header cut short
    assert elf_symbol(short, "useShadowMap") is None


def test_the_egl_plugin_names_its_shadow_switch():
    path = _egl_plugin_path()
    if path is None:
        pytest.skip("no EGL plugin in this PyBullet")
    symbol = elf_symbol(path, "useShadowMap")
    if symbol is None:
        pytest.skip("this build of the plugin has no symbol table")
    assert symbol[1] == 1  # a one-byte bool
    assert elf_symbol(path, "noSuchSymbolAnywhere") is None
    assert elf_symbol(path, "useShadowMa") is None  # whole names only


def test_load_address_finds_loaded_objects_only(tmp_path):
    assert isinstance(load_address(pybullet.__file__), int)  # an extension module: a shared object
    missing = tmp_path / "never_loaded.so"
    missing.write_bytes(b"")
    assert load_address(missing) is None


def test_loaded_symbol_says_why_a_symbol_cannot_be_had(tmp_path):
    missing = tmp_path / "never_loaded.so"
    missing.write_bytes(b"")
    for path in (None, str(missing)):
        with pytest.raises(SymbolUnavailable, match="the test object is not loaded in this process") as info:
            loaded_symbol(path, "glad_glViewport", "the test object")
        assert not info.value.lasting  # it may load later
    with pytest.raises(SymbolUnavailable, match=r"has no symbol table entry 'noSuchSymbolAnywhere' \(a stripped or "
                                                r"other build of pybullet\)") as info:
        loaded_symbol(pybullet.__file__, "noSuchSymbolAnywhere", "pybullet")
    assert info.value.lasting


def test_loaded_symbol_gives_where_the_egl_plugin_keeps_its_gl_table():
    client = renderer.connect()  # loads the plugin where EGL works
    try:
        path = _egl_plugin_path()
        if client.renderer != "egl" or elf_symbol(path, "glad_glViewport") is None:
            pytest.skip("no EGL plugin with a symbol table here")
        found, address, size = loaded_symbol(path, "glad_glViewport", "PyBullet's EGL plugin")
        assert found == path and size == 8  # a function pointer
        assert address == load_address(path) + elf_symbol(path, "glad_glViewport")[0]
    finally:
        renderer.release(client)
