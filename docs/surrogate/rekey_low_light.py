"""Move the shipped surrogate's low_light points to the low_light pool presets' k's, severity by severity.

The shipped surrogate (``weather_gym/surrogate/models/shipped.npz``) was fitted on logs at the pool presets of
the night camera before its colour went to half resolution (low_light@1..4 at k 0.755 / 0.843 / 0.890 / 0.917).
The pool presets were calibrated again for the new camera to the same damage (relative mAP on the calibration
pool within 0.010 of the study's levels, as before), at other k's. The surrogate is looked up by k, so until it
is refitted on logs of the new camera (``docs/surrogate/regenerate.sh``) each fitted point is moved to the k of
its severity: ``low_light@N`` in surrogate mode keeps the damage it had, and the k's are the shipped ones.

    python docs/surrogate/rekey_low_light.py        # from the repository root; rewrites shipped.npz
"""

from __future__ import annotations

from weather_gym.surrogate.model import SHIPPED_MODEL, load_model, save_model
from weather_gym.weather.presets import preset_spec

OLD = (0.755, 0.843, 0.890, 0.917)  # the k's the points were fitted at, low_light@1..4


def main() -> None:
    model = load_model(SHIPPED_MODEL)
    pts = model.points["low_light"]
    if [round(k, 3) for k, _ in pts] != list(OLD):
        raise SystemExit(f"the shipped surrogate's low_light points are at {[k for k, _ in pts]}, not {OLD}")
    new = [float(preset_spec("low_light", sev)[0]["k"]) for sev in (1, 2, 3, 4)]
    model.points["low_light"] = [(k, p) for k, (_, p) in zip(new, pts, strict=True)]
    model.meta["low_light_rekeyed"] = {"fitted_at": list(OLD), "now_at": new,
                                       "why": "pool presets calibrated again for the night camera with half-resolution colour"}
    save_model(model, SHIPPED_MODEL, overwrite=True)
    print(f"low_light points: {list(OLD)} -> {new}")


if __name__ == "__main__":
    main()
