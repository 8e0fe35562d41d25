"""Training: the cone detector (``detector``), the PPO driver (``policy``), the perception surrogate's logs and validation (``surrogate``)."""
