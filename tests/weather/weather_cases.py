"""Effect cases shared by the weather tests: every registry entry plus variants with their own code path."""

from __future__ import annotations

from weather_gym.weather import EFFECTS, make

#: Registry names plus the variants with a different code path.
VARIANTS = [(name, {}) for name in EFFECTS.names()] + [
    ("droplets", {"persistent": True}),
    ("droplets", {"mode": "refractive"}),
    ("droplets", {"mode": "refractive", "persistent": True}),
    ("dim", {"mode": "physical"}),
    ("dim", {"mode": "night"}),
    ("exposure", {"direction": "over", "gamma_error": 0.3, "flare": 0.1, "contrast": 0.5}),
    ("exposure", {"contrast": -0.6}),
    ("motion_blur", {"kind": "linear", "angle_deg": 30.0}),
]
VARIANT_IDS = [n + ("-" + "-".join(f"{k}={v}" for k, v in p.items()) if p else "") for n, p in VARIANTS]


def build(name: str, params: dict, k: float):
    return make(name, k=k, **params)
