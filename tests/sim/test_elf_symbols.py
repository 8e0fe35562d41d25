"""Symbols of a loaded shared object from its ELF symbol table."""

from __future__ import annotations

import pybullet
import pytest

from weather_gym.sim.elf_symbols import elf_symbol, load_address
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
