"""``weather-gym calibrate``: presets from sweep curves and measured perception levels (the study's method).

Examples:
    weather-gym calibrate --curve docs/calibration/curves.csv \\
        --measured docs/calibration/study_table2.csv --out presets.toml --report docs/calibration \\
        --dataset data/eval_peanut
    weather-gym calibrate --curve runs/sweep/curves.csv --measured ideal=data/real_clear \\
        --measured droplets@3=data/real_drops --out my_presets.toml --match absolute

Reads the mean curve of each condition's effect (droplets -> droplets, low_light -> dim; change with
``--use low_light=dim_physical``), reads off the k where it meets each measured severity (relative
drop by default), writes a presets TOML that ``weather_gym.weather.load_presets`` accepts, and a
report (Markdown + plots). With ``--dataset`` the chosen k are re-measured there.

Without ``--curve`` it **resolves** the shipped presets for one scenario instead (docs/calibration.md,
"Two meanings of a severity"): ``weather-gym calibrate --track skidpad --world realistic --detector
yolov8:my.onnx --out skidpad.toml`` renders a reference set of the scenario, finds each calibrated row's k
there, and writes the presets (k, interval, bootstrap error; ``k_source = "resolved"``) and a curve plot;
``--dataset DIR`` resolves on a clear recording of your own. Use the file with ``--presets FILE``.

A command line parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['calibrate', '--curve', 'runs/sweep/curves.csv', '--measured', 'ideal=data/real_clear', '--out', 'my_presets.toml'])
    >>> args.measured, args.match, args.metric
    (['ideal=data/real_clear'], 'relative', 'map50')
"""

from __future__ import annotations

import math
import shlex
import sys
from pathlib import Path

from weather_gym.camera.config import CameraConfig
from weather_gym.cli._camera_isp_arg import add_camera_model_arg, camera_model_arg
from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.cli._presets_arg import resolution_lines
from weather_gym.cli._runner_args import add_runner_args, check_runner_args
from weather_gym.core._io import check_output, declare_inputs, derived_outputs_replaceable
from weather_gym.core._option_alias import OneDefaultFormatter
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core._toml import read_toml
from weather_gym.core.errors import InputError, MissingInputError
from weather_gym.lab.calibration.calibrate import (
    calibrate,
    fill_from_curves,
    parse_use,
    remeasure,
    write_presets,
)
from weather_gym.lab.calibration.curve import load_curves
from weather_gym.lab.calibration.measured import load_measured
from weather_gym.lab.calibration.report import REPORT_FILES, study_points, write_report
from weather_gym.lab.calibration.resolve import Scenario, resolve_presets, write_resolved
from weather_gym.lab.calibration.resolve_plot import plot_resolution
from weather_gym.weather.presets import load_presets


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate", help="presets from sweep curves and measured mAP (read off k per severity)",
        description="Invert each effect's mAP-vs-k curve (from `weather-gym sweep`) at the levels measured in real "
                    "weather (a CSV table like the study's Table 2, or labelled COCO image sets scored here) and "
                    "write a presets TOML plus a calibration report. Matches the relative drop (mAP / ideal mAP "
                    "of the same domain) by default, because our detector is not the study's.",
        formatter_class=OneDefaultFormatter,
    )
    p.add_argument("--curve", action="append", type=Path, default=None,
                   help="curve file(s) written by `weather-gym sweep` (OUT/curves.csv); repeat for several. Without "
                        "--curve, calibrate RESOLVES the shipped presets for a scenario (--track or --dataset)")
    p.add_argument("--measured", action="append", default=None, metavar="TABLE|DIR|COND@SEV=DIR|ideal=DIR",
                   help="measured levels: a CSV (condition, severity, map and/or relative_to_ideal, optional domain), "
                        "or labelled COCO image sets whose mAP is measured here; repeat for several")
    p.add_argument("--out", type=Path, required=True, help="presets TOML to write (never overwritten without --overwrite)")
    add_overwrite_arg(p, help="replace --out and the report files if they exist")
    p.add_argument("--match", default="relative", choices=("relative", "absolute"),
                   help="relative: mAP / ideal mAP of the same domain (default; detector-independent); absolute: mAP")
    p.add_argument("--use", action="append", default=None, metavar="CONDITION=CURVE",
                   help="curve label per condition (defaults droplets=droplets, low_light=dim)")
    p.add_argument("--domain", default=None, help="domain of the measured rows to use (default: the only one)")
    p.add_argument("--metric", default="map50", help="curve column to match: map50 (mAP@0.5 over the classes present) or map50_blue_yellow "
                        "(over blue and yellow, the two classes the study scored)")
    p.add_argument("--dataset-id", default=None, help="use only curve rows of this dataset_id")
    p.add_argument("--model-id", default=None, help="use only curve rows of this model_id")
    p.add_argument("--dataset", type=Path, default=None,
                   help="with --curve: re-measure every chosen k on this COCO set (achieved mAP; default: interpolate "
                        "the curve); without: resolve the presets on this clear recording (a COCO set)")
    r = p.add_argument_group("resolving presets for a scenario (no --curve; docs/calibration.md)")
    r.add_argument("--track", action="append", default=None,
                   help="track to resolve for (name, random:SEED, a cone CSV; repeat for several)")
    r.add_argument("--world", default="plain", choices=("plain", "realistic"), help="the world rendered")
    r.add_argument("--camera", type=Path, default=None, metavar="FILE.toml",
                   help="camera (a TOML of CameraConfig fields: width, height, fov_deg, ...; default: the env's)")
    add_camera_model_arg(r, "the env's, realistic", "the camera's finishing stage")
    r.add_argument("--frames", type=int, default=Scenario.frames, help="frames of the reference set (one chunk)")
    r.add_argument("--max-frames", type=int, default=Scenario.max_frames,
                   help="widen the reference set up to this many frames while a damage is not known within --tolerance")
    r.add_argument("--tolerance", type=float, default=0.02,
                   help="half-width of the 95 %% interval (bootstrap over episodes) a resolved damage must be known within")
    r.add_argument("--plot", type=Path, default=None, help="curve plot PNG (default: next to --out, OUT_STEM.png)")
    p.add_argument("--seeds", type=int, default=5, help="weather realisations per preset when re-measuring")
    add_detector_args(p, what="scores the measured image sets and re-measures", legacy_model=True)
    p.add_argument("--base", type=Path, default=None,
                   help="presets file for conditions without measured levels (default: the shipped one)")
    p.add_argument("--report", type=Path, default=None,
                   help="folder for calibration_report.md and plots (default: next to --out, OUT_STEM_report/)")
    p.add_argument("--study-points", type=Path, default=None,
                   help="the study's Figure-7 points (effect,k,map) to draw beside our curves in the report")
    p.add_argument("--source", default=None, help="text for the presets' 'source' field (default: this command)")
    add_runner_args(p, what="re-measurement cells (or, resolving, processes sharing the render and the detector)",
                    resumable=False)
    p.set_defaults(func=_run)


def _merge_curves(paths, metric, dataset_id, model_id):
    curves = {}
    for path in paths:
        for label, c in load_curves(path, metric=metric, dataset_id=dataset_id, model_id=model_id).items():
            if label in curves:
                raise InputError(f"curve {label!r} appears in both {curves[label].source} and {path}; give it once")
            curves[label] = c
    return curves


def _run(args) -> int:
    if args.curve is None:
        return _run_resolve(args)
    if args.measured is None:
        raise InputError("--curve needs --measured (the levels to read off k at)")
    if args.track is not None:
        raise InputError("--track resolves presets for a scenario and takes no --curve; give one or the other")
    declare_inputs(args.base, args.dataset, args.study_points, *args.curve,
                   *(Path(m.rpartition("=")[2]) for m in args.measured))
    check_output(args.out, overwrite=args.overwrite, suffixes=(".toml",), what="--out")
    report_dir = args.report or args.out.with_name(args.out.stem + "_report")
    replace_report = derived_outputs_replaceable(report_dir / "remeasured.csv",
                                                 [report_dir / f for f in REPORT_FILES if f != "remeasured.csv"],
                                                 overwrite=args.overwrite)
    if args.seeds < 1:
        raise InputError(f"--seeds must be >= 1, got {args.seeds}")
    check_runner_args(args)
    if args.dataset is not None and not args.dataset.exists():
        raise MissingInputError(f"--dataset {args.dataset} not found")
    curves = _merge_curves(args.curve, args.metric, args.dataset_id, args.model_id)
    use = parse_use(args.use)
    study = study_points(args.study_points) if args.study_points is not None else None
    detector = detector_spec_from_args(args)
    levels = load_measured(args.measured, detector, progress=not args.no_progress)
    base = load_presets(args.base)["presets"]
    descriptions = {(c, s): t.get("description", "") for c, sev in base.items() for s, t in sev.items()}
    calibs = calibrate(curves, levels, match=args.match, use=use, domain=args.domain, descriptions=descriptions)
    if args.dataset is not None:
        remeasure(calibs, curves, args.dataset, report_dir / "remeasured.csv", seeds=tuple(range(args.seeds)),
                  model=detector, workers=args.workers, backend=args.backend, ray_address=args.ray_address,
                  progress=not args.no_progress, metric=args.metric)
    else:
        fill_from_curves(calibs, curves)
    command = shlex.join(["weather-gym", *sys.argv[1:]]) if "calibrate" in sys.argv[1:2] else None
    used = sorted({c.curve for c in calibs})
    meta = {
        "source": args.source or command or "weather_gym.lab.calibration.calibrate",
        "match": args.match,
        "metric": f"{args.metric} (pycocotools)",
        "domain": calibs[0].domain if calibs else "",
        "curves": {lb: curves[lb].source for lb in used},
        "detector_model_id": ", ".join(sorted({curves[lb].model_id for lb in used})),
        "eval_dataset_id": ", ".join(sorted({curves[lb].dataset_id for lb in used})),
        "eval_ideal_map": {lb: round(curves[lb].ideal, 4) for lb in used},
    }
    path = write_presets(calibs, args.out, meta=meta, base=args.base, overwrite=args.overwrite)
    write_report(calibs, curves, report_dir, command=command, presets_path=path, study=study, levels=levels,
                 overwrite=replace_report)
    print(f"{'condition':<10} S  target  k      interval         achieved  reachable")
    for c in calibs:
        if c.severity == 0:
            continue
        ach = f"{c.achieved:.3f}" if math.isfinite(c.achieved) else "n/a  "
        print(f"{c.condition:<10} {c.severity}  {c.target:.3f}   {c.k:.3f}  [{c.k_interval[0]:.3f}, {c.k_interval[1]:.3f}]"
              f"   {ach}     {'yes' if c.reachable else 'NO'}")
        if c.note:
            print(f"    note: {c.note}")
    print(f"wrote {path} and {report_dir / 'calibration_report.md'}")
    return 0


def _scenario_from_args(args, detector) -> Scenario:
    camera = CameraConfig()
    if args.camera is not None:
        table = read_toml(args.camera, "--camera file")
        try:
            camera = CameraConfig(**table.get("camera", table))
        except TypeError as exc:
            raise InputError(f"--camera {args.camera}: {exc}") from None
    if args.track is None and args.dataset is None:
        raise InputError("give --track TRACK (repeatable) or --dataset DIR (a clear recording) to resolve for, "
                         "or --curve/--measured to calibrate from sweep curves")
    if args.track is not None and args.dataset is not None:
        raise InputError("give --track or --dataset, not both")
    if args.dataset is not None:
        declare_inputs(args.dataset)
        if not args.dataset.exists():
            raise MissingInputError(f"--dataset {args.dataset} not found")
    return Scenario(tracks=tuple(args.track or ()), scene=args.world, camera=camera,
                    camera_model=camera_model_arg(args.camera_model), detector=detector,
                    dataset=None if args.dataset is None else str(args.dataset), frames=args.frames,
                    max_frames=args.max_frames)


def _run_resolve(args) -> int:
    """``calibrate --track ...`` / ``--dataset DIR`` without ``--curve``: resolve, write presets and a plot."""
    declare_inputs(args.base)
    check_output(args.out, overwrite=args.overwrite, suffixes=(".toml",), what="--out")
    plot = args.plot or args.out.with_suffix(".png")
    check_output(plot, overwrite=args.overwrite, suffixes=(".png",), what="--plot")
    detector = detector_spec_from_args(args)
    scenario = _scenario_from_args(args, detector)
    res = resolve_presets(scenario, presets=args.base, tolerance=args.tolerance, progress=not args.no_progress,
                          workers=args.workers)  # --workers: one process per CPU unless given (same k's)
    for line in resolution_lines(res):
        print(line)
    path = write_resolved(res, args.out, presets=args.base, scenario=scenario, overwrite=args.overwrite)
    plot_resolution(res, plot, overwrite=args.overwrite)
    print(f"wrote {path} and {plot}; use it with --presets {path} (or WEATHER_GYM_PRESETS={path})")
    return 0
