"""``weather-gym train``: a driver on the cone-list observation, in three stages: a clone of a scripted
driver (behaviour cloning with DAgger), PPO fine-tuning, and the policy that laps held-out tracks
best kept as the model; logs, checkpoints, resume, and a usable model after Ctrl-C.

**Warm start.** ``--pretrain EXPERT`` (default ``gt_pure_pursuit``, the scripted driver on the true
pose; ``none``: PPO from scratch) is cloned with DAgger on the training envs
(:mod:`weather_gym.lab.training.policy.pretrain`; ``--pretrain-steps``, ``--dagger-rounds``,
``--pretrain-epochs``, ``--pretrain-log-std``); ``checkpoints/ppo_0_steps.zip`` holds the clone.

**Observation.** The policy reads the cone list ``Dict(cones, mask, state)`` through
``weather_gym.agents.sb3_features.ConeListPolicy``, by default from the perception surrogate (the
detector's fitted statistics, nothing rendered; env ``i`` in ``--surrogate-weathers[i % len]``) and
through the cone memory (``--cone-memory``, ``--detection-range``). ``gt_cones`` is geometric ground
truth degraded with ``--noise`` (``OracleNoise``); ``detector`` / ``oracle`` render a frame per step
(with ``--weather``: ``WeatherRandomizer`` fields). The detector on a weathered frame gives the same
observation, so the trained policy is evaluated through weather and the detector
(``examples/evaluate_policy.py``, ``weather-gym evaluate --agent sb3``; ``docs/rl.md``).

**Hyper-parameters** come from a file in rl-zoo3's YAML format (``--hyperparams``, default the
shipped :data:`weather_gym.lab.training.policy.HYPERPARAMS`, section ``--hyperparams-key``): ``n_envs``,
``n_timesteps``, ``policy``, ``normalize``, ``policy_kwargs`` and PPO's own keywords. Options given on
the command line (``--n-envs``, ``--timesteps``, ``--learning-rate``, ...) override single values.

**Tracks.** Env ``i`` drives ``--track[i % len]``; three quarters of the episodes start at a random
point of the track (drawn from the reset seed), a quarter at the start line.

**The model kept.** After the warm start, every ``--eval-freq`` PPO steps and at the end, the policy
drives the held-out ``--eval-track`` tracks (never trained on) from the start line in each of
``--eval-weathers`` through ``--eval-perception``
(:mod:`weather_gym.lab.training.policy.selection`); the best (most laps, then fewest cones, then
least time) goes to ``best/`` and, when the run ends, becomes ``model.zip``. Progress and the main
statistics are printed as lines and appended to ``train.log``.

**Outputs** in ``--out``: ``model.zip`` and ``model.json`` (the env it was trained on: what
``examples/evaluate_policy.py`` reads), ``checkpoints/ppo_<N>_steps.zip`` each with its
``ppo_<N>_steps.json``, ``best/best_model.zip`` with ``best/best_model.json``, ``train.log``,
``logs/<segment>/progress.csv`` and TensorBoard event files, ``learning_curve.png``,
``pretrain_curve.png``, ``run.json`` (command, settings, segments, wall time). ``--resume`` continues
from the newest complete checkpoint up to ``--timesteps``; ``--overwrite`` replaces the run in a
non-empty folder (never without it), removing only the files a run writes (``RUN_FILES``); a folder
holding no run is refused. One run writes a folder at a time (a lock on ``--out``). **Ctrl-C or
SIGTERM** stops the run and still writes ``model.zip`` (the policy as it is), ``model.json``, the
learning curve and ``run.json`` (its segment marked interrupted, with the signal; exit status 130 or
143). Every hyper-parameter and option is checked first against its declared range
(``weather_gym.lab.training.policy.hyperparams.Hyperparams``).

Example:
    >>> args = build_parser().parse_args(["--out", "runs/x", "--n-envs", "2"])
    >>> hp = resolve_hyperparams(args)
    >>> hp["n_envs"], hp["n_timesteps"], hp["ppo"]["n_steps"], hp["policy"].rsplit(".", 1)[-1], args.pretrain
    (2, 100000, 256, 'ConeListPolicy', 'gt_pure_pursuit')
"""


from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import shutil
import signal
import sys
import time
import warnings
import zipfile
from pathlib import Path
from typing import Any

from weather_gym.agents.cone_memory import ConeMemoryConfig
from weather_gym.core._io import _make_parent, atomic_path, atomic_write_json
from weather_gym.core._lock import exclusive_folder
from weather_gym.core._option_alias import alias
from weather_gym.core.errors import (
    FileFormatError,
    InputError,
    LimitError,
    MissingInputError,
    OutputExistsError,
    Terminated,
)
from weather_gym.core.limits import MAX_CAMERA_SIDE, check_seed, parse_size
from weather_gym.lab.training.policy import HYPERPARAMS
from weather_gym.lab.training.policy.hyperparams import (
    POLICIES,
    Bound,
    load_hyperparams,
    ppo_arguments,
    resolve_hyperparams,
)
from weather_gym.lab.training.policy.pretrain import PretrainConfig, pretrain
from weather_gym.lab.training.policy.progress import (
    RunLog,
    Selector,
    echo_to_tty,
    ppo_callbacks,
    recorded_best,
)
from weather_gym.lab.training.policy.run_outputs import (
    RUN_FILES,
    RUN_RECORD,
    TRAIN_LOG,
    _checkpoint_steps,
    _metadata_callbacks,
    _remove_run,
    holds_run,
    latest_checkpoint,
    model_metadata,
    plot_learning_curve,
    plot_pretrain_curve,
)
from weather_gym.lab.training.policy.selection import HeldOutConfig, held_out_laps
from weather_gym.lab.training.policy.training_env import (
    LapSuccess,
    RandomStart,
    make_training_env,
    takes_oracle_noise,
)
from weather_gym.pipeline.modes import CONES, modes_where, perception_mode
from weather_gym.tracks import split_track_specs

__all__ = ["DEFAULT_TRACKS", "DEFAULT_NOISE", "LapSuccess", "RandomStart", "build_parser", "latest_checkpoint",
           "load_hyperparams", "make_training_env", "model_metadata", "plot_learning_curve", "plot_pretrain_curve",
           "resolve_hyperparams", "train", "RUN_FILES"]

_BASE_TRACKS = ("peanut", "fsds_training", "b_shape", "jellybean", "hairpin", "oval", "random:1", "random:2")
DEFAULT_TRACKS = (*_BASE_TRACKS, *(f"reverse:{t}" for t in _BASE_TRACKS))
"""The 8 training layouts and the same 8 driven the other way round (every turn both ways)."""
DEFAULT_EVAL_TRACKS = ("small_track", "mirror:hairpin", "mirror:peanut")
"""Held out: never driven in training (``small_track``; the mirror images of ``hairpin`` and of ``peanut``, the
tightest layout: where a policy that cuts turns hits cones, docs/rl.md)."""
DEFAULT_EVAL_TRACK = ",".join(DEFAULT_EVAL_TRACKS)
DEFAULT_SURROGATE_WEATHERS = ("clear", "droplets@1", "droplets@2", "droplets@3", "droplets@4", "low_light@1",
                              "low_light@2", "clear")
"""Env ``i`` of ``--perception surrogate`` drives the ``i % 8``-th: every calibrated weather in which the detector
still reports cones."""
DEFAULT_EVAL_WEATHERS = ("clear", "droplets@1", "droplets@2", "droplets@3", "low_light@1")
"""The weathers the shipped driver is held to (docs/rl.md): the held-out drives that pick the model."""
DEFAULT_EXPERT = "gt_pure_pursuit"
"""The warm start's teacher (``--pretrain``; ``none``: PPO from the network's initial weights)."""
DEFAULT_DETECTION_RANGE = 30.0
"""``--detection-range``: this frame's cones beyond it are left out of what the policy reads (m)."""
DEFAULT_HYPERPARAMS_KEY = "WeatherGym/ConeTrackCones-v0"
DEFAULT_NOISE = {"miss_prob": 0.15, "range_noise": 0.05, "bearing_noise": 0.01, "false_positives": 0.3,
                 "swap_prob": 0.02, "max_range": 22.0}
"""OracleNoise of training: roughly what the detector does wrong on clean frames (see docs/rl.md)."""
PERCEPTIONS = tuple(modes_where(observation=CONES))
"""The perception modes PPO can train on: those that give a cone list."""
EVAL_MAX_STEPS = 1800
"""Step limit of a held-out evaluation episode (60 s: a lap of small_track takes about 20 s)."""
INTERRUPTED = 130
"""Exit status after Ctrl-C (the model so far is saved)."""
TERMINATED = 143
"""Exit status after SIGTERM (the model so far is saved, as after Ctrl-C)."""
RUN_OPTIONS = {"max_steps": Bound(int, 1, 1_000_000, option="--max-steps"),
               "eval_freq": Bound(int, 0, 10**9, option="--eval-freq"),
               "eval_max_steps": Bound(int, 1, 1_000_000, option="--eval-max-steps"),
               "eval_episodes": Bound(int, 1, 1000, option="--eval-episodes"),
               "checkpoint_freq": Bound(int, 1, 10**9, option="--checkpoint-freq"),
               "torch_threads": Bound(int, 1, 256, option="--torch-threads")}
"""The declared bounds of ``weather-gym train``'s own options (the hyper-parameters': :class:`Hyperparams`)."""
VEC_KINDS = ("auto", "split", "dummy", "subproc")
"""``--vec``: how the training envs are vectorised (see :func:`vec_kind`)."""


def vec_kind(vec: str, perception: str, n_envs: int, cores: int | None = None) -> str:
    """The vector env ``--vec`` asks for; ``"auto"`` resolves to ``"split"`` (``SplitVecEnv``: a
    little over half the envs in a second process) for render-free perception with at least 2 envs and 2 usable
    cores, else ``"dummy"``. Every kind gives the same observations (each env is seeded as in
    ``DummyVecEnv``).

    Example:
        >>> vec_kind("auto", "surrogate", 8, cores=2), vec_kind("auto", "detector", 8, cores=2)
        ('split', 'dummy')
    """
    if vec not in VEC_KINDS:
        raise InputError(f"--vec must be one of {', '.join(VEC_KINDS)}, got {vec!r}")
    if vec != "auto":
        return vec
    if cores is None:
        cores = usable_cores()
    render_free = not perception_mode(perception).renders_frames
    return "split" if render_free and n_envs >= 2 and cores >= 2 else "dummy"


# ------------------------------------------------------------------ command line
def build_parser(p: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """The options of ``weather-gym train`` (and ``examples/train_ppo.py``), added to ``p``."""
    p = p or argparse.ArgumentParser(prog="weather-gym train", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="run folder (see --resume, --overwrite)")
    p.add_argument("--resume", action=argparse.BooleanOptionalAction, default=False,
                   help="continue the run in --out from its newest checkpoint (--no-resume, the default: a new run)")
    p.add_argument("--overwrite", action="store_true",
                   help="start a new run in a --out that holds one: what that run wrote (model, checkpoints, best/, "
                        "logs/steps*, run.json, curves) is removed first, nothing else; a folder holding no run is "
                        "refused")
    p.add_argument("--hyperparams", type=Path, default=HYPERPARAMS,
                   help="hyper-parameter file in rl-zoo3's YAML format (default: the shipped ppo.yml)")
    p.add_argument("--hyperparams-key", default=DEFAULT_HYPERPARAMS_KEY, help="its section")
    p.add_argument("--timesteps", type=int, default=None, help="total environment steps (default: n_timesteps)")
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs, env i drives tracks[i %% len] "
                   "(default: n_envs)")
    p.add_argument("--vec", choices=VEC_KINDS, default="auto",
                   help="split: 5 of 8 envs in a second process, stepped at the same time (SplitVecEnv; "
                        "render-free perception on >= 2 cores); dummy: DummyVecEnv, one process; subproc: "
                        "SubprocVecEnv, a process per env (rendered perception); auto: split for gt_cones/"
                        "surrogate with >= 2 envs and >= 2 usable cores, else dummy")
    p.add_argument("--env-id", default="WeatherGym/ConeTrack-v0",
                   help="the scenario (an id with camera images, so the policy evaluates through the detector)")
    p.add_argument("--track", dest="tracks", default=",".join(DEFAULT_TRACKS), help="training tracks, comma-separated")
    alias(p, "--track", "--tracks")
    p.add_argument("--eval-track", default=DEFAULT_EVAL_TRACK,
                   help="held-out tracks (comma-separated, never trained on): driven from the start line to pick "
                        "the model (see --eval-weathers)")
    p.add_argument("--perception", choices=PERCEPTIONS, default="surrogate",
                   help="surrogate: the detector's statistics in each env's weather, nothing rendered; gt_cones: "
                        "geometry + --noise, nothing rendered; oracle: rendered ground truth; detector")
    p.add_argument("--noise", default=json.dumps(DEFAULT_NOISE),
                   help="OracleNoise fields (JSON) for gt_cones/oracle; '{}' for perfect cones")
    p.add_argument("--weather", default=None,
                   help="WeatherRandomizer fields (JSON) for rendered perception, e.g. "
                        "'{\"presets\": [\"droplets\", \"low_light\", \"rain\"], \"severities\": [0, 1, 2, 3]}'")
    p.add_argument("--camera", default=None, help="camera resolution WxH (default: the scenario's)")
    p.add_argument("--max-steps", type=int, default=1200, help="episode step limit while training (30 = 1 s)")
    for opt, typ in (("n-steps", int), ("batch-size", int), ("n-epochs", int), ("learning-rate", float),
                     ("gamma", float), ("ent-coef", float)):
        p.add_argument(f"--{opt}", type=typ, default=None, help="PPO's, overriding the file's")
    p.add_argument("--log-std-init", type=float, default=None,
                   help="initial log std of the actions (policy_kwargs; the file's -0.5: std 0.61 of [-1, 1])")
    p.add_argument("--eval-freq", type=int, default=25_000,
                   help="PPO env steps between held-out evaluations (also one after the warm start and one at the "
                        "end); 0: none, the last policy is the model")
    p.add_argument("--eval-episodes", type=int, default=1, help="held-out episodes per track and weather (seeds)")
    p.add_argument("--eval-weathers", default=",".join(DEFAULT_EVAL_WEATHERS),
                   help="weathers of the held-out drives: every --eval-track in each, from the start line")
    p.add_argument("--eval-perception", choices=PERCEPTIONS, default="surrogate",
                   help="perception of the held-out drives (surrogate: the detector's statistics, nothing rendered; "
                        "detector: rendered frames through the weather and the ONNX detector, slower)")
    p.add_argument("--eval-max-steps", type=int, default=EVAL_MAX_STEPS,
                   help="step limit of a held-out drive (30 = 1 s)")
    p.add_argument("--checkpoint-freq", type=int, default=25_000, help="env steps between checkpoints")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--surrogate-weathers", default=",".join(DEFAULT_SURROGATE_WEATHERS),
                   help="--perception surrogate: weathers, env i drives the i-th (cycled)")
    p.add_argument("--init", type=Path, default=None,
                   help="start from this saved PPO model (e.g. weather_gym/agents/models/ppo_cones.zip): fine-tuning")
    p.add_argument("--torch-threads", type=int, default=1, help="torch threads (1: the envs share the cores)")
    p.add_argument("--cone-memory", action=argparse.BooleanOptionalAction, default=True,
                   help="the policy reads the cone list with the confirmed cones seen in the last second added "
                        "(RememberedCones; model.json records its settings, and the sb3 agent drives with the same; "
                        "--no-cone-memory: this frame's list only)")
    p.add_argument("--detection-range", default=str(DEFAULT_DETECTION_RANGE),
                   help="with the cone memory: this frame's cones farther than this (m) are left out, in training "
                        "and when the model drives; 'none': all")
    g = p.add_argument_group("warm start (behaviour cloning with DAgger before PPO; weather_gym.lab.training.policy.pretrain)")
    g.add_argument("--pretrain", default=DEFAULT_EXPERT, metavar="EXPERT",
                   help="a registered agent that labels the training envs' observations, e.g. gt_pure_pursuit "
                        "(the true pose) or mapper_pure_pursuit; the policy is cloned from it before PPO; "
                        "none: no warm start, PPO from the network's initial weights")
    g.add_argument("--pretrain-steps", type=int, default=120_000, help="env steps of expert-labelled data, all rounds")
    g.add_argument("--dagger-rounds", type=int, default=4,
                   help="round 0 drives with the expert, round r with the student but for a share beta**r")
    g.add_argument("--dagger-beta", type=float, default=0.5, help="expert-driven share base (see --dagger-rounds)")
    g.add_argument("--pretrain-epochs", type=int, default=20, help="passes over all the data after each round")
    g.add_argument("--pretrain-log-std", type=float, default=-1.6,
                   help="the policy's log std after pretraining, PPO's exploration from there (-1.6: std 0.2)")
    g.add_argument("--teacher-narrow-width", type=float, default=0.0, metavar="M",
                   help="the teacher (gt_pure_pursuit) slows where the track is narrower than this many metres, "
                        "its corner limit scaled by (width / M)**2; 0: off")
    return p


def usable_cores() -> int:
    """The cores this process may run on (its affinity): ``vec_kind`` splits the envs only with two or more."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _check_args(args: argparse.Namespace) -> None:
    """The options that are no hyper-parameter, against their declared bounds (:data:`RUN_OPTIONS`)."""
    if getattr(args, "pretrain", None) in ("none", ""):
        args.pretrain = None
    least = 0 if getattr(args, "pretrain", None) is not None else 1  # 0: the cloned policy is the model
    if args.timesteps is not None and args.timesteps < least:
        raise LimitError(f"--timesteps must be an integer >= 1 (0 only with --pretrain), got {args.timesteps}")
    for name, bound in RUN_OPTIONS.items():
        bound.check(getattr(args, name), bound.option or f"--{name.replace('_', '-')}")
    check_seed(args.seed, what="--seed")


def _check_n_envs(n_envs: int, kind: str, cpus: int | None = None) -> None:
    """``--vec subproc`` starts a process per env: at most 4 per CPU core, as ``make_vec_env``'s
    ``"async"`` mode; ``dummy`` and ``split`` run them in one or two processes (at most
    :data:`weather_gym.lab.training.policy.hyperparams.MAX_N_ENVS`, checked with the hyper-parameters)."""
    most = 4 * (cpus or os.cpu_count() or 1)
    if kind == "subproc" and n_envs > most:
        raise LimitError(f"n_envs {n_envs} with --vec subproc would start {n_envs} processes: at most {most} "
                         "(4 per CPU core, as make_vec_env's async mode); use --vec dummy or split (envs in one or "
                         "two processes) for more")


def _settings(args: argparse.Namespace, hp: dict[str, Any]) -> dict[str, Any]:
    env_kwargs: dict[str, Any] = {}
    if args.camera:
        w, h = parse_size(args.camera, what="--camera", example="336x188")
        if max(w, h) > MAX_CAMERA_SIDE:
            raise LimitError(f"--camera {args.camera}: each side must be at most {MAX_CAMERA_SIDE} pixels")
        env_kwargs["camera"] = {"width": w, "height": h}
    try:
        noise = json.loads(args.noise)
        weather = json.loads(args.weather) if args.weather else None
    except json.JSONDecodeError as exc:
        raise InputError(f"--noise / --weather must be JSON objects: {exc}") from None
    for opt, value in (("--noise", noise), ("--weather", weather)):
        if value is not None and not isinstance(value, dict):
            raise InputError(f"{opt} must be a JSON object of fields, got {value!r}")
    tracks = list(split_track_specs(args.tracks))
    if not tracks:
        raise InputError("--track is empty")
    held_out = _held_out_config(args, tracks)
    mode = perception_mode(args.perception)
    if weather and not mode.renders_frames:
        raise InputError(f"--weather acts on camera images; {args.perception} renders none (use --perception detector, "
                         "or --surrogate-weathers)")
    own_weather = mode.takes_weather and not mode.renders_frames  # draws cones in its own weather
    sw = [w.strip() for w in args.surrogate_weathers.split(",") if w.strip()] if own_weather else []
    out = {"env_id": args.env_id, "perception": args.perception,
           "noise": noise if takes_oracle_noise(mode) else {},
           "max_steps": args.max_steps, "env_kwargs": env_kwargs, "weather": weather, "tracks": tracks,
           "hyperparams": {k: v for k, v in hp.items() if k != "n_timesteps"}}
    if sw:
        out["surrogate_weathers"] = sw
    if args.init is not None:
        if not Path(args.init).is_file():
            raise MissingInputError(f"--init {args.init}: no such model file")
        if not zipfile.is_zipfile(args.init):
            raise FileFormatError(f"--init {args.init}: not a saved SB3 model (a .zip written by model.save)")
        out["init"] = str(args.init)
    if getattr(args, "cone_memory", False):  # the tuning, so a resume or a driver uses the same
        out["cone_memory"] = ConeMemoryConfig(detection_range=_detection_range(args)).to_dict()
    if args.eval_freq > 0:
        out["held_out"] = dataclasses.asdict(held_out)
    if getattr(args, "pretrain", None) is not None:
        out["pretrain"] = dataclasses.asdict(_pretrain_config(args))
    return out


def _detection_range(args: argparse.Namespace) -> float | None:
    value = str(getattr(args, "detection_range", "none")).strip().lower()
    if value in ("none", ""):
        return None
    try:
        out = float(value)
    except ValueError:
        out = float("nan")
    if not 0.0 < out < float("inf"):
        raise InputError(f"--detection-range must be a distance in metres > 0 or 'none', got {value!r}")
    return out


def _split(text: str) -> tuple[str, ...]:
    return tuple(t.strip() for t in str(text).split(",") if t.strip())


def _held_out_config(args: argparse.Namespace, training_tracks: list[str]) -> HeldOutConfig:
    """The held-out drives of ``--eval-*``; a training track among them is refused."""
    config = HeldOutConfig(tracks=split_track_specs(args.eval_track), weathers=_split(args.eval_weathers),
                           perception=args.eval_perception, max_steps=args.eval_max_steps,
                           episodes=args.eval_episodes)
    for t in config.tracks:
        if t in training_tracks:
            raise InputError(f"--eval-track {t} is also a training track: it would not be held out")
    return config


def _pretrain_config(args: argparse.Namespace) -> PretrainConfig:
    return PretrainConfig(expert=args.pretrain, steps=args.pretrain_steps, rounds=args.dagger_rounds,
                          epochs=args.pretrain_epochs, beta=args.dagger_beta, log_std=args.pretrain_log_std,
                          teacher_narrow_width=args.teacher_narrow_width)


def _close(env: Any) -> None:
    try:
        env.close()
    except (EOFError, OSError):  # SubprocVecEnv workers already gone (Ctrl-C reaches them too)
        pass


def _start_run(args: argparse.Namespace, s: dict[str, Any]) -> tuple[Path | None, dict[str, Any]]:
    """(checkpoint to resume from or None, run record) for ``--out`` (held locked by the caller): the run to
    continue (``--resume``, with the same settings ``s``), or a new one in an empty folder; with
    ``--overwrite`` a folder holding a run loses what that run wrote (:data:`RUN_FILES`), nothing else."""
    out: Path = args.out
    checkpoints = out / "checkpoints"
    run_file = out / RUN_RECORD
    if args.resume:
        ckpt = latest_checkpoint(checkpoints)
        if ckpt is None or not run_file.is_file():
            raise InputError(f"--resume: no checkpoint in {checkpoints} (or no {run_file}); start a new run instead")
        try:
            run = json.loads(run_file.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise FileFormatError(f"--resume: {run_file} is not a run record ({exc})") from None
        if not holds_run(out):
            raise FileFormatError(f"--resume: {run_file} is not a run record (no settings and segments)")
        if run["settings"] != json.loads(json.dumps(s)):
            raise InputError(f"--resume with other settings than the run in {out}: {run['settings']} vs {s}")
        return ckpt, run
    if any(out.iterdir()):
        if not args.overwrite:
            raise OutputExistsError(f"{out} exists and is not empty; pass --resume to continue that run, "
                                    "--overwrite to start a new one there, or give another --out")
        if not holds_run(out):
            raise OutputExistsError(f"--overwrite: {out} holds no training run (no {RUN_RECORD} of one), so nothing "
                                    "in it is replaced; give an empty or new --out")
        _remove_run(out)
    return None, {"settings": s, "segments": []}


def _policy(name: str) -> Any:
    """The policy class or SB3 name of ``policy`` (one of :data:`POLICIES`; nothing else is imported)."""
    if name == POLICIES[0]:
        from weather_gym.agents.sb3_features import ConeListPolicy

        return ConeListPolicy
    if name in POLICIES:
        return name
    raise InputError(f"policy must be one of {list(POLICIES)}, got {name!r}")


def _ignore_further_sigterm() -> None:
    """After the first stop the run saves; a SIGTERM then must not cut the save (``_train`` restores the handler)."""
    try:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    except ValueError:  # not the main thread
        pass


def train(args: argparse.Namespace) -> int:
    """Run (or resume) the training of ``args``; 0 when done, :data:`INTERRUPTED` after Ctrl-C,
    :data:`TERMINATED` after SIGTERM (through ``weather_gym.cli.run_command``; the model so far saved)."""
    import torch

    _check_args(args)
    if args.resume and args.overwrite:
        raise InputError("--resume continues the run in --out and --overwrite replaces it: give one")
    hp = resolve_hyperparams(args)
    s = _settings(args, hp)
    kind = vec_kind(args.vec, s["perception"], hp["n_envs"])
    _check_n_envs(hp["n_envs"], kind)
    _policy(hp["policy"])
    out: Path = args.out
    if args.resume and not out.is_dir():
        raise InputError(f"--resume: {out} is no run folder; start a new run instead")
    torch.set_num_threads(args.torch_threads)
    tracks, sw = s["tracks"], s.get("surrogate_weathers") or ["clear"]
    make = [lambda i=i, lean_info=True: make_training_env(
        s["env_id"], tracks[i % len(tracks)], s["perception"], s["noise"], s["max_steps"], s["env_kwargs"],
        s["weather"], surrogate_weather=sw[i % len(sw)], lean_info=lean_info,
        cone_memory=s.get("cone_memory")) for i in range(hp["n_envs"])]
    make[0]().close()  # a bad setting fails here, in this process, with its message, before --out is touched
    _make_parent(out / RUN_RECORD)
    with exclusive_folder(out, busy=f"another weather-gym train is writing {out} (it holds the folder's lock); "
                                    "wait for it to end, or give another --out"):
        return _train(args, hp, s, make, kind)


def _train(args: argparse.Namespace, hp: dict[str, Any], s: dict[str, Any], make: list, kind: str) -> int:
    """The run in the locked ``--out``."""
    from stable_baselines3.common.callbacks import CallbackList, ProgressBarCallback
    from stable_baselines3.common.logger import configure

    out: Path = args.out
    checkpoints = out / "checkpoints"
    run_file = out / RUN_RECORD
    ckpt, run = _start_run(args, s)
    atomic_write_json(run_file, run, indent=2, overwrite=True)  # the folder holds a run from now on (kill -9 too)
    log = RunLog(out / TRAIN_LOG)

    def meta(steps: int) -> dict[str, Any]:
        return model_metadata(s, hp, args.seed, s.get("held_out", {}).get("tracks", [args.eval_track])[0], steps,
                              run.get("pretrain"))

    n_envs, total = hp["n_envs"], hp["n_timesteps"]
    started = time.time()
    model = None
    start_steps = 0
    stopped: str | None = None  # the signal that stopped the run: "SIGINT" (Ctrl-C) or "SIGTERM"
    vec = logger = None
    sigterm = signal.getsignal(signal.SIGTERM)
    selector = _selector(s, out, meta, log)
    log(_describe_run(args, hp, s, ckpt))
    try:
        vec = _vec_envs(args, hp, s, make, kind)
        segment = f"steps{_checkpoint_steps(ckpt):09d}"
        if (out / "logs" / segment).exists():  # a resume from the checkpoint written after the warm start
            segment += f"-{len(run['segments'])}"
        logger = configure(str(out / "logs" / segment), ["csv", "tensorboard"])
        model, vec = _model(args, hp, ckpt, vec)
        if ckpt is None and "pretrain" in s:
            stopped = _warm_start(args, model, make, run, log)
            if stopped is None:  # a resume continues from the cloned policy, not from scratch
                _save_checkpoint(model, checkpoints, meta)
                atomic_write_json(run_file, run, indent=2, overwrite=True)
        model.set_logger(logger)
        checkpoint_cb, _ = _metadata_callbacks(meta, checkpoints, max(args.checkpoint_freq // n_envs, 1), out / "best")
        # tqdm + rich (rl_zoo3's dependencies); tqdm marks its rich bar experimental on every run: not the user's concern
        warnings.filterwarnings("ignore", message="rich is experimental/alpha")
        progress = ProgressBarCallback() if echo_to_tty() else None
        callbacks = CallbackList([*([progress] if progress else []), checkpoint_cb,
                                  *ppo_callbacks(total, log, selector, args.eval_freq)])
        start_steps = model.num_timesteps
        if total - start_steps > 0 and stopped is None:
            stopped = _learn(model, total - start_steps, callbacks, progress)
        if stopped is None and selector is not None and selector.last_steps != model.num_timesteps:
            stopped = _last_drives(selector, model, logger)
        _save_final(out, model, meta, selector if stopped is None else None)
    except (KeyboardInterrupt, Terminated) as exc:  # before a model to save: the segment still says so
        stopped = _stop(exc)
        raise
    finally:
        for closing in (logger, vec):
            if closing is not None:
                _close(closing)
        run["segments"].append({"from_steps": int(start_steps),
                                "to_steps": int(model.num_timesteps) if model is not None else None,
                                "wall_s": round(time.time() - started, 1), "interrupted": stopped is not None,
                                "signal": stopped, "command": shlex.join([sys.executable, *sys.argv])})
        run["wall_s_total"] = round(sum(seg["wall_s"] for seg in run["segments"]), 1)
        if out.is_dir():
            atomic_write_json(run_file, run, indent=2, overwrite=True)
        if stopped is not None and sigterm is not None:
            try:
                signal.signal(signal.SIGTERM, sigterm)
            except ValueError:  # not the main thread
                pass
    _log_end(out, run, int(model.num_timesteps), log)
    if stopped is not None:
        again = (f"continue with the same command and --resume (from the newest checkpoint in {checkpoints})"
                 if latest_checkpoint(checkpoints) is not None else
                 "no checkpoint yet (stopped in the warm start): run the same command with --overwrite to start again")
        print(f"stopped early: {again}, or evaluate {out / 'model.zip'} as it is", file=sys.stderr)
        return TERMINATED if stopped == "SIGTERM" else INTERRUPTED
    return 0


def _selector(s: dict[str, Any], out: Path, meta: Any, log: Any) -> Selector | None:
    """The held-out drives that pick the model (None with ``--eval-freq 0``), with the best a resumed run recorded."""
    if "held_out" not in s:
        return None
    held_out = HeldOutConfig.from_dict(s["held_out"])

    def drive(model: Any) -> Any:
        return held_out_laps(lambda o: model.predict(o, deterministic=True)[0], held_out, s["env_id"],
                             s["env_kwargs"], s.get("cone_memory"))

    return Selector(drive, out / "best", meta, log, best=recorded_best(out / "best" / "best_model.json"))


def _learn(model: Any, steps: int, callbacks: Any, progress: Any) -> str | None:
    """PPO for ``steps`` more env steps; the signal that stopped it, or None."""
    try:
        model.learn(total_timesteps=steps, callback=callbacks, reset_num_timesteps=False)
    except (KeyboardInterrupt, Terminated) as exc:
        stopped = _stop(exc)
        if progress is not None:
            progress.on_training_end()  # close the bar (its live display) that learn() left open
        print(f"{'terminated (SIGTERM)' if stopped == 'SIGTERM' else 'interrupted'} after "
              f"{model.num_timesteps} steps: saving the model so far", file=sys.stderr)
        return stopped
    return None


def _log_end(out: Path, run: dict[str, Any], steps: int, log: Any) -> None:
    """The curves, and the run's last line: which policy ``model.zip`` is."""
    curve = plot_learning_curve(out)
    warm = plot_pretrain_curve(out, run.get("pretrain"))
    kept = json.loads((out / "model.json").read_text(encoding="utf-8"))
    held = kept.get("held_out")
    chosen = (f"; model.zip is the policy of {kept['timesteps']} PPO steps, the best on the held-out drives "
              f"({held['laps']}/{held['episodes']} laps, {held['cones']} cones)" if held else "")
    log(f"saved {out / 'model.zip'} after {steps} steps{chosen}; {run['wall_s_total']:.0f} s of training "
        f"in {len(run['segments'])} segment(s); learning curve: {curve}" + (f"; warm start: {warm}" if warm else ""))


def _warm_start(args: argparse.Namespace, model: Any, make: list, run: dict[str, Any], log: Any) -> str | None:
    """Clone ``--pretrain`` into ``model.policy`` (the record into ``run``); the signal that stopped it, or None."""
    teach = [m(lean_info=False) for m in make]  # the same envs with the whole info (the expert's)
    try:
        run["pretrain"] = pretrain(model.policy, teach, _pretrain_config(args), args.seed, progress=echo_to_tty(),
                                   log=log)
    except (KeyboardInterrupt, Terminated) as exc:
        print("interrupted while pretraining: saving the policy so far", file=sys.stderr)
        return _stop(exc)
    finally:
        for env in teach:
            env.close()
    return None


def _last_drives(selector: Selector, model: Any, logger: Any) -> str | None:
    """The held-out drives of the last policy (or of the clone, with ``--timesteps 0``); a stop's signal or None."""
    try:
        selector.evaluate(model, logger)
    except (KeyboardInterrupt, Terminated) as exc:
        return _stop(exc)
    return None


def _describe_run(args: argparse.Namespace, hp: dict[str, Any], s: dict[str, Any], ckpt: Path | None) -> str:
    """The run's first log line: what it trains on, how, and how the model is picked."""
    warm = (f"warm start: {s['pretrain']['steps']} steps of behaviour cloning of {s['pretrain']['expert']} in "
            f"{s['pretrain']['rounds']} DAgger rounds, then " if "pretrain" in s and ckpt is None else "")
    ho = s.get("held_out")
    pick = (f"the model kept: the most laps (then fewest cones, then fastest) from the start line on "
            f"{', '.join(ho['tracks'])} in {', '.join(ho['weathers'])} ({ho['perception']}), after the warm start "
            f"and every {args.eval_freq} PPO steps" if ho else "the model kept: the last policy (--eval-freq 0)")
    start = f"resuming from {ckpt.name}; " if ckpt is not None else ""
    return (f"{start}training {args.out}: {hp['n_envs']} envs on {len(s['tracks'])} tracks, perception "
            f"{s['perception']}, {warm}PPO up to {hp['n_timesteps']} steps; {pick}; log: {args.out / TRAIN_LOG}")


def _save_checkpoint(model: Any, checkpoints: Path, meta: Any) -> None:
    """``ppo_<N>_steps.zip`` (with the reward normaliser's state and the ``.json`` that makes it complete)."""
    steps = int(model.num_timesteps)
    zip_path = checkpoints / f"ppo_{steps}_steps.zip"
    with atomic_path(zip_path, overwrite=True) as tmp:
        model.save(str(tmp))
    stats = model.get_vec_normalize_env()
    if stats is not None:
        with atomic_path(checkpoints / f"ppo_vecnormalize_{steps}_steps.pkl", overwrite=True) as tmp:
            stats.save(str(tmp))
    atomic_write_json(zip_path.with_suffix(".json"), meta(steps), indent=2, overwrite=True)


def _save_final(out: Path, model: Any, meta: Any, selector: Any) -> None:
    """``model.zip`` and ``model.json``: the best held-out policy of a finished run (with the step count of the
    last one), else (a stopped run, or no held-out drives) the policy as it is."""
    best = out / "best" / "best_model.zip"
    if selector is not None and selector.best is not None and best.is_file():
        record = json.loads(best.with_suffix(".json").read_text(encoding="utf-8"))
        with atomic_path(out / "model.zip", overwrite=True) as tmp:
            shutil.copyfile(best, tmp)
        atomic_write_json(out / "model.json", {**record, "last_timesteps": int(model.num_timesteps)}, indent=2,
                          overwrite=True)
        return
    with atomic_path(out / "model.zip", overwrite=True) as tmp:  # this run's own file
        model.save(str(tmp))
    atomic_write_json(out / "model.json", meta(model.num_timesteps), indent=2, overwrite=True)


def _vec_envs(args: argparse.Namespace, hp: dict[str, Any], s: dict[str, Any], make: list, kind: str):
    """The training envs (``--vec`` ``kind``), normalised as the file says."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecMonitor, VecNormalize

    from weather_gym.lab.training.policy.split_vec_env import SplitVecEnv

    vec: VecEnv = VecMonitor({"split": SplitVecEnv, "subproc": SubprocVecEnv, "dummy": DummyVecEnv}[kind](make))  # infos: INFO_KEYS only
    normalize = hp["normalize"]
    if normalize is not False:  # rl-zoo3's `normalize`: VecNormalize keywords; its state is saved with each checkpoint
        vec = VecNormalize(vec, **{"gamma": hp["ppo"].get("gamma", 0.99), **normalize})
    return vec


def _model(args: argparse.Namespace, hp: dict[str, Any], ckpt: Path | None, vec: Any) -> tuple[Any, Any]:
    """(PPO model, training env): new (from the file's policy and keywords, or ``--init``), or the checkpoint ``ckpt``."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    if ckpt is None and args.init is not None:
        vec.seed(args.seed)
        model = PPO.load(str(args.init), env=vec, device="cpu")
        model.num_timesteps = 0
    elif ckpt is None:
        vec.seed(args.seed)
        model = PPO(_policy(hp["policy"]), vec, seed=args.seed, device="cpu", verbose=0,
                    policy_kwargs=dict(hp["policy_kwargs"]), **ppo_arguments(hp))
    else:
        print(f"resuming from {ckpt}")
        stats = ckpt.with_name(ckpt.name.replace("ppo_", "ppo_vecnormalize_").replace(".zip", ".pkl"))
        if hp["normalize"] is not False and stats.is_file():
            vec = VecNormalize.load(str(stats), vec.venv)
        model = PPO.load(str(ckpt), env=vec, device="cpu")
        vec.seed(args.seed + model.num_timesteps)
    return model, vec


def _stop(exc: BaseException) -> str:
    """The signal behind ``exc`` (Ctrl-C or SIGTERM); further SIGTERMs are ignored while the run saves."""
    _ignore_further_sigterm()
    return "SIGTERM" if isinstance(exc, Terminated) else "SIGINT"
