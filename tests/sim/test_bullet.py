"""PyBullet's build-time banner stays off the user's terminal (``weather_gym.sim.bullet``)."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("code", [
    "import weather_gym.sim.world",
    "from weather_gym.cli import main; main(['lap', '--help'])",
])
def test_importing_the_simulator_prints_no_banner(code):
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert "pybullet build time" not in out.stdout + out.stderr


def test_the_quiet_import_still_gives_pybullet():
    from weather_gym.sim.bullet import pybullet

    client = pybullet.connect(pybullet.DIRECT)
    try:
        assert pybullet.getNumBodies(physicsClientId=client) == 0
    finally:
        pybullet.disconnect(client)
