"""``weather-gym surrogate``: log the full pipeline, fit the perception surrogate, validate it.

Examples:
    weather-gym surrogate log --track small_track --weather droplets@3 --seed-list 0,1 --steps 600 --out logs/d3.npz
    weather-gym surrogate fit logs/*.npz --out model.npz
    weather-gym surrogate validate --track hairpin --full-logs scratch/val_logs --out docs/surrogate/validation

A ``fit`` command line, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['surrogate', 'fit', 'logs/a.npz', 'logs/b.npz', '--out', 'model.npz'])
    >>> args.action, [str(p) for p in args.logs], str(args.out)
    ('fit', ['logs/a.npz', 'logs/b.npz'], 'model.npz')
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.cli._seed_arg import int_list, seed_list
from weather_gym.core._io import check_output, declare_inputs, exclusive
from weather_gym.core._option_alias import alias
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.core.limits import parse_size
from weather_gym.lab.training.surrogate.record import loggable_modes, record
from weather_gym.lab.training.surrogate.validate import validate
from weather_gym.pipeline.modes import detector_mode, perception_mode
from weather_gym.surrogate.log import concat_logs, load_log, save_log
from weather_gym.surrogate.model import fit, save_model
from weather_gym.tracks import load_track


def _names(text: str) -> list[str]:
    return [x.strip() for x in text.split(",") if x.strip()]


def _camera_size(text: str | None) -> tuple[int, int] | None:
    """``--camera WxH`` (None: the scenario's camera)."""
    return None if text is None else parse_size(text, what="--camera", example="336x188")


def register(sub) -> None:
    p = sub.add_parser("surrogate", help="perception surrogate: log the full pipeline, fit, validate",
                       description="A statistical model of what the detector reports in each weather "
                                   "(docs/surrogate.md): log full-pipeline runs, fit the model, validate it.")
    s = p.add_subparsers(dest="action", metavar="ACTION", required=True)

    lg = s.add_parser("log", help="drive the full pipeline and log every true cone and false positive (.npz)",
                      formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n")[1])
    lg.add_argument("--track", default="small_track", help="comma-separated tracks (default %(default)s)")
    lg.add_argument("--weather", action="append", default=None, metavar="SPEC",
                    help="weather spec, repeatable (e.g. clear, droplets@3, low_light@2; default clear)")
    lg.add_argument("--seed-list", dest="seeds", default="0", help="comma-separated episode seeds (default %(default)s)")
    alias(lg, "--seed-list", "--seeds")
    lg.add_argument("--steps", type=int, default=600, help="steps per episode, at most (default %(default)s)")
    lg.add_argument("--agent", default="gt_pure_pursuit", choices=("gt_pure_pursuit", "mapper_pure_pursuit"),
                    help="driver: gt_pure_pursuit (the true track) or mapper_pure_pursuit (drives on the cone "
                         "list; its lap metrics are kept) (default %(default)s)")
    lg.add_argument("--perception", default=detector_mode().name, choices=loggable_modes(),
                    help="a perception that reports detections: detector, the full pipeline (default); "
                         "surrogate, the same tables from the surrogate")
    add_detector_args(lg, what="the detector whose errors are logged")
    lg.add_argument("--out", type=Path, required=True, metavar="LOG.npz", help="output log")
    add_overwrite_arg(lg)
    lg.set_defaults(func=_log)

    ft = s.add_parser("fit", help="fit the surrogate model from logs")
    ft.add_argument("logs", nargs="+", type=Path, metavar="LOG.npz", help="logs written by `surrogate log`")
    ft.add_argument("--out", type=Path, required=True, metavar="MODEL.npz", help="output model")
    add_overwrite_arg(ft)
    ft.set_defaults(func=_fit)

    va = s.add_parser("validate", help="surrogate vs full pipeline on a track: report (markdown + PNG)")
    va.add_argument("--model", type=Path, default=None, help="surrogate model (default: the shipped one)")
    va.add_argument("--track", default="hairpin", help="track (not used for fitting; default %(default)s)")
    va.add_argument("--conditions", default="droplets,low_light", help="conditions (default %(default)s)")
    va.add_argument("--severities", default="0,1,2,3,4", help="severities (default %(default)s)")
    va.add_argument("--seed-list", dest="seeds", default="0,1,2", help="full-pipeline seeds, comma-separated (default %(default)s)")
    alias(va, "--seed-list", "--seeds")
    va.add_argument("--surrogate-seeds", default="0,1,2,3,4,5,6,7,8,9", help="surrogate seeds (default %(default)s)")
    va.add_argument("--steps", type=int, default=900, help="steps per lap, at most (default %(default)s)")
    va.add_argument("--full-logs", type=Path, default=None, metavar="DIR",
                    help="folder of full-pipeline logs of this track (clear.npz, droplets_3.npz, ...): reused, "
                         "missing ones recorded there (default OUT/full_logs)")
    va.add_argument("--weathers", default=None, metavar="SPECS",
                    help="comma-separated weathers to check instead of --conditions x --severities "
                         "(e.g. clear,droplets@3,rain@2)")
    va.add_argument("--camera", default=None, metavar="WxH",
                    help="camera size both pipelines run at (default: the scenario's, 672x376)")
    va.add_argument("--out", type=Path, required=True, metavar="DIR", help="report folder (report.md, PNGs, JSON)")
    add_overwrite_arg(va)
    va.set_defaults(func=_validate)


def _log(args) -> int:
    check_output(args.out, overwrite=args.overwrite, suffixes=(".npz",), what="surrogate log")
    if args.steps < 1:
        raise InputError(f"--steps must be >= 1, got {args.steps}")
    tracks = _names(args.track)
    if not tracks:
        raise InputError("--track: no track given")

    for t in tracks:
        load_track(t)
    seeds = seed_list(args.seeds, "--seed-list")
    detector = detector_spec_from_args(args) if perception_mode(args.perception).runs_detector else None
    with exclusive(args.out, message=f"another run is writing {args.out}; wait for it or choose another --out"):
        log = record(tracks=tracks, weathers=args.weather or ["clear"], seeds=seeds, steps=args.steps,
                     detector=detector, agent=args.agent, perception=args.perception,
                     progress=lambda line: print(line, file=sys.stderr, flush=True))
        save_log(log, args.out, overwrite=args.overwrite)
    print(f"wrote {args.out}: {len(log.episodes)} episodes, {len(log)} frames, {len(log.cones['frame'])} cone rows, "
          f"{len(log.fps['frame'])} false positives")
    return 0


def _fit(args) -> int:
    declare_inputs(*args.logs)
    check_output(args.out, overwrite=args.overwrite, suffixes=(".npz",), what="surrogate model")
    model = fit(concat_logs([load_log(p) for p in args.logs]), sources=[str(p) for p in args.logs])
    save_model(model, args.out, overwrite=args.overwrite)
    print(model.summary())
    print(f"wrote {args.out}")
    return 0


def _validate(args) -> int:
    declare_inputs(args.model)
    if args.steps < 1:
        raise InputError(f"--steps must be >= 1, got {args.steps}")

    validate(model=args.model, track=args.track, conditions=_names(args.conditions),
             severities=int_list(args.severities, "--severities"), seeds=seed_list(args.seeds, "--seed-list"),
             surrogate_seeds=seed_list(args.surrogate_seeds, "--surrogate-seeds"), steps=args.steps,
             full_logs=args.full_logs, camera=_camera_size(args.camera),
             weathers=_names(args.weathers) if args.weathers else None,
             out=args.out, overwrite=args.overwrite,
             progress=lambda line: print(line, file=sys.stderr, flush=True))
    return 0
