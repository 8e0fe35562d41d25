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

from weather_gym._io import check_output, declare_inputs, derived_outputs_replaceable
from weather_gym._option_alias import OneDefaultFormatter
from weather_gym._output_args import add_overwrite_arg
from weather_gym.calibration.calibrate import calibrate, fill_from_curves, parse_use, remeasure, write_presets
from weather_gym.calibration.curve import load_curves
from weather_gym.calibration.measured import load_measured
from weather_gym.calibration.report import REPORT_FILES, study_points, write_report
from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.cli._runner_args import add_runner_args, check_runner_args
from weather_gym.errors import InputError, MissingInputError
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
    p.add_argument("--curve", action="append", type=Path, required=True,
                   help="curve file(s) written by `weather-gym sweep` (OUT/curves.csv); repeat for several")
    p.add_argument("--measured", action="append", required=True, metavar="TABLE|DIR|COND@SEV=DIR|ideal=DIR",
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
                   help="re-measure every chosen k on this COCO set (achieved mAP); default: interpolate the curve")
    p.add_argument("--seeds", type=int, default=5, help="weather realisations per preset when re-measuring")
    add_detector_args(p, what="scores the measured image sets and re-measures", legacy_model=True)
    p.add_argument("--base", type=Path, default=None,
                   help="presets file for conditions without measured levels (default: the shipped one)")
    p.add_argument("--report", type=Path, default=None,
                   help="folder for calibration_report.md and plots (default: next to --out, OUT_STEM_report/)")
    p.add_argument("--study-points", type=Path, default=None,
                   help="the study's Figure-7 points (effect,k,map) to draw beside our curves in the report")
    p.add_argument("--source", default=None, help="text for the presets' 'source' field (default: this command)")
    add_runner_args(p, what="re-measurement cells", resumable=False)
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
        "source": args.source or command or "weather_gym.calibration.calibrate",
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
