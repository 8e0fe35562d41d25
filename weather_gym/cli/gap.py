"""``weather-gym gap MEASURED_DIR --model MODEL.toml --out OUT_DIR``: the sim-versus-measured gap workflow.

Simulates the measured frames through the weather model, finds where simulation and measurement
disagree (image signals and the detector, bootstrapped over frames), names the missing effects,
adds them with fitted parameters and reports the held-out gap before and after. See docs/gap.md.

Examples:
    weather-gym gap data/measured --model model.toml --out out/gap
    weather-gym gap data/real_wet --reference data/real_clear --out out/gap_wet      # same camera
    weather-gym gap data/real_wet --reference data/real_clear --mode did --track small_track --out out/gap_did
    weather-gym gap data/measured --out out/gap_clean --seed 3     # no --model: the clean simulator

The second command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['gap', 'data/real_wet', '--reference', 'data/real_clear', '--out', 'out/gap_wet'])
    >>> str(args.measured), str(args.reference), args.mode
    ('data/real_wet', 'data/real_clear', 'auto')
"""

from __future__ import annotations

from pathlib import Path

from weather_gym.cli._camera_isp_arg import add_camera_model_arg, camera_model_arg
from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.cli._seed_arg import seed_arg
from weather_gym.core._io import declare_inputs
from weather_gym.core.errors import InputError, MissingInputError
from weather_gym.lab.gap.workflow import GapConfig, run_gap
from weather_gym.sim.config import SCENES


def register(sub) -> None:
    p = sub.add_parser("gap", help="find and fix the gap between simulated and measured frames",
                       description="Compare measured frames with the simulator under a weather model, name the "
                                   "effects the model is missing, add them with fitted parameters and show the "
                                   "held-out gap shrink. Writes report.json, model.toml, report.md and plots.")
    p.add_argument("measured", type=Path, help="measured data: a COCO folder (annotations.json, images/)")
    p.add_argument("--model", type=Path, default=None,
                   help="weather model TOML ([[effects]] name, k, ...); default: the clean simulator")
    p.add_argument("--out", type=Path, required=True, help="output folder (an existing report is never overwritten)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the split, bootstrap and effects (default %(default)s)")
    p.add_argument("--reference", type=Path, default=None, metavar="CLEAR_DIR",
                   help="measured clear frames of the same camera (a COCO folder): the model is applied to them "
                        "and compared with MEASURED (same-camera mode), or used for difference-in-differences")
    p.add_argument("--mode", choices=("auto", "paired", "unpaired", "same-camera", "did"), default="auto",
                   help="paired: re-render every view (needs track and pose per frame); unpaired: compare "
                        "distributions over the whole sets; same-camera: apply the model to --reference; did: "
                        "difference-in-differences with the simulator (needs --reference and a --track); auto "
                        "(default): same-camera with --reference, else paired when poses are present")
    p.add_argument("--track", action="append", default=None,
                   help="track(s) to render in unpaired mode when the records name none (repeatable)")
    p.add_argument("--sim-frames", type=int, default=None, help="frames to render in unpaired mode (default: as measured)")
    p.add_argument("--scene", choices=SCENES, default=None,
                   help="simulator world of unpaired / did renders (default: the records' world, else the default world)")
    add_camera_model_arg(p, "the records' camera model when they all agree, else realistic",
                         "camera model of unpaired / did renders: realistic, ideal or a TOML file of CameraModel fields")
    p.add_argument("--held-out", type=float, default=0.5, help="fraction of frames held out (default %(default)s)")
    p.add_argument("--fit-frames", type=int, default=32,
                   help="fitting frames used by the parameter search (default %(default)s)")
    p.add_argument("--max-steps", type=int, default=4, help="at most this many effects are added (default %(default)s)")
    p.add_argument("--candidates", default=None,
                   help="comma-separated effect names that may be added (default: every weather effect and "
                        "every measured member: tone_curve, noise_level, radial_gain, blur_kernel)")
    p.add_argument("--alpha", type=float, default=0.01, help="family-wise significance level (default %(default)s)")
    p.add_argument("--compare-width", type=int, default=672,
                   help="frames wider than this are scaled down once on loading (default %(default)s)")
    p.add_argument("--no-prune", action="store_true",
                   help="keep every effect the loop added (default: drop those the held-out gap does not need)")
    add_detector_args(p)
    p.add_argument("--cache", type=Path, default=None, help="folder for the clean renders (default OUT/cache)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing report in --out")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=_run)


def _run(args) -> int:
    declare_inputs(args.measured, args.reference, args.model)  # the report never lands in (or on) an input
    if not args.measured.is_dir():
        raise MissingInputError(f"measured data folder {args.measured} not found")
    if args.reference is not None and not args.reference.is_dir():
        raise MissingInputError(f"--reference folder {args.reference} not found")
    if args.model is not None and not args.model.is_file():
        raise MissingInputError(f"model file {args.model} not found")
    if args.compare_width < 64:
        raise InputError(f"--compare-width must be >= 64 pixels, got {args.compare_width}")
    detector = detector_spec_from_args(args)
    cands = None
    if args.candidates:
        cands = tuple(c.strip() for c in args.candidates.split(",") if c.strip())
    config = GapConfig(seed=args.seed, mode=args.mode, tracks=tuple(args.track) if args.track else None,
                       sim_frames=args.sim_frames, scene=args.scene, camera_model=camera_model_arg(args.camera_model),
                       held_out=args.held_out, fit_frames=args.fit_frames,
                       max_steps=args.max_steps, candidates=cands, alpha=args.alpha, detector=detector,
                       compare_width=args.compare_width, prune=not args.no_prune, progress=not args.quiet)
    report = run_gap(args.measured, args.model, args.out, config, reference=args.reference, cache_dir=args.cache,
                     overwrite=args.overwrite)
    missing = ", ".join(report["missing_effects"]) or "none"
    pb, pa = report.get("perception_gap_before"), report.get("perception_gap_after")
    print(f"mode: {report['mode']} ({report['mode_reason']})")
    print(f"verdict: {report['verdict']}")
    for d in (report.get("domain") or {}).get("differences", []):
        print(f"domain difference ({d['name']}): {d['detail']}")
    if report.get("perception_warning"):
        print(f"note: {report['perception_warning']}")
    if pb is not None and pa is not None:
        print(f"perception gap |mAP_sim - mAP_measured| (held-out): {pb:.3f} -> {pa:.3f}")
    print(f"image-signal gap (held-out): {report['gap_before']:.3f} -> {report['gap_after']:.3f}")
    print(f"missing effects: {missing}")
    print(f"wrote {args.out / 'report.json'}, {report['model']}, {args.out / 'report.md'}")
    return 0
