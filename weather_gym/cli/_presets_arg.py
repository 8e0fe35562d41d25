"""``--presets pool|resolved|FILE``: which k a ``CONDITION@SEVERITY`` means, for every command that takes weather.

* ``resolved`` - resolved for the command's own scenario (track, camera, world, detector): the k that makes
  this scenario's detector lose what the study measured (``weather_gym.lab.calibration.resolve``; a minute
  or so the first time a scenario is used, cached after);
* ``pool`` - the shipped presets, calibrated once on the pool of tracks for the shipped detector (fast; the
  meaning of older results);
* ``FILE`` - a presets file (``weather-gym calibrate --track ... --out FILE`` writes one).

Not given (:func:`default_choice`): ``$WEATHER_GYM_PRESETS`` when set (``pool``, ``resolved`` or a file),
else ``resolved`` where the command has a scenario and its weather names a preset that resolution changes
(``lap``, ``evaluate``, ``degrade --reference DIR``), else the pool presets. Explicit ``NAME:K`` specs are
never changed.

Example:
    >>> import argparse
    >>> p = argparse.ArgumentParser(); add_presets_arg(p)
    >>> p.parse_args(["--presets", "pool"]).presets
    'pool'
    >>> presets_from_arg("pool", None).name
    'presets.toml'
    >>> default_choice("pool", "low_light@2")  # given: as given (not given: $WEATHER_GYM_PRESETS, else resolved)
    'pool'
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from weather_gym.core._io import declare_inputs
from weather_gym.core.errors import MissingInputError, ResolutionError
from weather_gym.envs.registration import scenario_of
from weather_gym.envs.scenario import build_config
from weather_gym.lab.calibration.resolve import Resolution, Scenario, resolve_presets, resolves
from weather_gym.weather.presets import DEFAULT_PRESETS, load_presets, presets_meaning

__all__ = ["add_presets_arg", "default_choice", "env_scenario", "presets_from_arg", "resolution_lines"]


def add_presets_arg(p: Any) -> None:
    """Add ``--presets`` to the parser ``p``."""
    p.add_argument("--presets", default=None, metavar="pool|resolved|FILE",
                   help="what CONDITION@SEVERITY means: 'resolved' (k resolved for this run's track, camera, world "
                        "and detector; minutes the first time, cached after; docs/calibration.md), 'pool' "
                        "(the shipped presets, calibrated on the pool of tracks) or a presets FILE (default: "
                        "$WEATHER_GYM_PRESETS, else resolved where the run has a scenario)")


def default_choice(value: str | None, weather: Any, mode: Any = None) -> str | None:
    """``--presets`` as given, or its default for ``weather`` (any weather spec, or a list of
    ``(condition, severity)``): ``$WEATHER_GYM_PRESETS``'s meaning, ``resolved`` when it is unset and
    ``weather`` names a preset that resolution changes (a calibrated ``CONDITION@SEVERITY``, severity above 0),
    else None (the weather layer's default: the pool presets, or the file ``$WEATHER_GYM_PRESETS`` names).
    ``mode``: the perception mode of the run; one whose camera frames do not go through the weather (the
    surrogate, whose table holds the pool presets' k's; ground truth; LiDAR) keeps the pool presets."""
    if value is not None:
        return value
    if mode is not None and not (mode.renders_frames and mode.takes_weather):
        return None
    meaning = presets_meaning()
    if meaning == "pool":
        return "pool"
    return "resolved" if meaning == "resolved" and resolves(weather) else None


def env_scenario(env_id: str, track: str | None, detector: Any = None,
                 env_kwargs: dict[str, Any] | None = None) -> Scenario:
    """The scenario presets are resolved for in a run of ``env_id`` on ``track`` (None: the scenario's):
    its track, camera, camera model and world (``env_kwargs`` override them as in ``make_env``), and
    ``detector`` (the one in the loop)."""
    overrides = {k: v for k, v in (env_kwargs or {}).items() if k in ("camera", "camera_model", "sim")}
    if track is not None:
        overrides["track"] = track
    cfg = build_config(scenario_of(env_id), overrides or None)
    return Scenario(tracks=(cfg.track,), scene=cfg.sim.scene, camera=cfg.camera, camera_model=cfg.camera_model,
                    detector=detector)


def presets_from_arg(value: str | None, scenario: Callable[[], Scenario] | None, *,
                     progress: bool = True) -> Path | None:
    """The presets file of ``--presets`` (None: not given). ``resolved`` resolves ``scenario()`` (cached)."""
    if value is None:
        return None
    if value == "pool":
        return DEFAULT_PRESETS
    if value == "resolved":
        if scenario is None:
            raise ResolutionError("--presets resolved needs a scenario to resolve for (a track, or --reference DIR)")
        res = resolve_presets(scenario(), progress=progress)
        for line in resolution_lines(res):
            print(line)
        if res.path is None:
            raise ResolutionError(f"{res.scenario}: resolved, but there is no writable cache folder to keep the "
                                  "presets file in; set WEATHER_GYM_CACHE to a writable folder")
        return res.path
    path = Path(value)
    declare_inputs(path)
    if not path.is_file():
        raise MissingInputError(f"--presets: {value} not found (give a presets file, pool or resolved)")
    load_presets(path)  # a bad file fails here, naming the key
    return path


def resolution_lines(res: Resolution) -> list[str]:
    """What a resolution found, for a printout: one line per row (k pool -> k resolved, damage)."""
    head = (f"presets resolved for {res.scenario} ({'cached' if res.cached else f'{res.seconds:.0f} s'}; "
            f"{res.n_frames} frames, {res.n_cones} cones, clear mAP {res.clear_map:.3f})")
    lines = [head]
    for r in res.rows:
        if r.severity == 0:
            continue
        lines.append(f"  {r.condition}@{r.severity}: k {r.k_pool:.3f} (pool) -> {r.k:.3f} (resolved), relative mAP "
                     f"{r.achieved:.3f} ± {r.se:.3f} (target {r.target:.3f})" + (f"; {r.note}" if r.note else ""))
    if res.path is not None:
        lines.append(f"  presets file: {res.path}")
    return lines
