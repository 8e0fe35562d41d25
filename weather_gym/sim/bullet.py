"""PyBullet, imported once for the whole simulator without the build-time banner it prints.

PyBullet's module prints ``pybullet build time: ...`` to the C library's stdout when it is first
imported; every ``weather-gym`` command would show it (twice where a worker imports it too). The
simulator's modules import PyBullet from here, so the first import happens inside
:func:`~weather_gym.sim.quiet.quiet_c_output` (the descriptors are redirected only for the import).

Example:
    >>> from weather_gym.sim.bullet import pybullet as p
    >>> p.ER_TINY_RENDERER
    65536
"""

from __future__ import annotations

from weather_gym.sim.quiet import quiet_c_output

with quiet_c_output():
    import pybullet

__all__ = ["pybullet"]
