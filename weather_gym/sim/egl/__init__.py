"""EGL frame plumbing of the simulator: the plugin's shadow map switched off (``shadow_map``) or reused
(``shadow_reuse``, opt-in), found through the plugin's ELF symbols (``elf_symbols``, ``gl_table``).

Example:
    >>> from weather_gym.sim.egl import shadow_reuse
    >>> shadow_reuse.VERIFIED_BUILDS
    ('3.2.7',)
"""
