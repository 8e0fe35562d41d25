"""EGL frame plumbing of the simulator: the plugin's shadow map switched off or reused (opt-in), found through its ELF symbols."""
