"""An entry of the EGL plugin's GL pointer table pointed at a function of our own, and again after
the plugin reloads its table."""

from __future__ import annotations

import pytest

from weather_gym.sim import renderer
from weather_gym.sim.egl import shadow_reuse as egl_shadow_reuse
from weather_gym.sim.egl.elf_symbols import SymbolUnavailable
from weather_gym.sim.egl.gl_table import ONE_ENUM, GLTableEntry


@pytest.fixture
def egl_client():
    client = renderer.connect()
    if client.renderer != "egl":
        renderer.release(client)
        pytest.skip("EGL does not load here")
    yield client
    renderer.release(client)


def test_an_entry_is_pointed_again_after_a_release_and_refused_when_unknown(egl_client, monkeypatch):
    if egl_shadow_reuse._hook is not None:  # this process's hook (the suite runs with the reuse on)
        egl_shadow_reuse._hook._entry.release()
    monkeypatch.setattr(egl_shadow_reuse, "_hook", None)
    monkeypatch.setattr(egl_shadow_reuse, "_reason", None)
    monkeypatch.setenv("WEATHER_GYM_SHADOW_MAP_REUSE", "1")  # the hook on its glViewport entry
    with pytest.raises(SymbolUnavailable, match="no symbol table entry 'glad_glNoSuchFunction'"):
        GLTableEntry("glNoSuchFunction", ONE_ENUM(lambda mask: None))
    if egl_shadow_reuse.unavailable_reason() is not None:
        pytest.skip(f"no GL table here: {egl_shadow_reuse.unavailable_reason()}")
    entry = egl_shadow_reuse._hook._entry  # the process's glViewport entry (one hook per entry)
    assert entry.ensure()  # the fixture's new EGL context reloaded the table where the hook was made earlier
    before = entry.repointed
    assert entry.ensure() and entry.repointed == before  # pointed at ours already
    entry.release()  # as the plugin does when it reloads its table
    assert entry.ensure() and entry.repointed == before + 1
    entry.release()  # the table given back: the default frames of later tests patch nothing
