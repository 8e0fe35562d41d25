"""``weather-gym sweep``: the detector's mAP versus an effect's k on a fixed rendered set (resumable).

Examples:
    weather-gym sweep --weather droplets --k-grid 0:1:0.05 --seeds 5 --dataset data/eval_peanut --out runs/sweep
    weather-gym sweep --weather droplets,dim,dim:k:mode=physical --k-grid 0:1:0.05 --seeds 5 \\
        --dataset data/eval_peanut --out docs/calibration

Writes OUT/curves.csv (tidy: effect, spec, k, seed, dataset_id, model_id, status, error, elapsed_s,
map50, map, ap50_<class>, recall, recall_<range>, ...), OUT/curves.png (mean and spread per effect),
OUT/curves_recall.png (recall by range) and OUT/sweep.json (what was run). Re-running the same
command skips finished cells.

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['sweep', '--weather', 'droplets', '--k-grid', '0:1:0.05', '--seeds', '5', '--dataset', 'data/eval_peanut', '--out', 'runs/sweep'])
    >>> args.seeds, str(args.dataset), str(args.out)
    (5, 'data/eval_peanut', 'runs/sweep')
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

import numpy as np

from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.cli._runner_args import add_runner_args, check_runner_args
from weather_gym.core._io import declare_inputs
from weather_gym.core._option_alias import OneDefaultFormatter
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError, MissingInputError
from weather_gym.lab.calibration.curve import load_curves
from weather_gym.lab.calibration.sweep import (
    CURVE_FILE,
    SweepEffect,
    make_sweep_cells,
    parse_effect,
    parse_k_range,
    parse_seeds,
    run_sweep,
)
from weather_gym.lab.evaluation.runner import check_results_path
from weather_gym.weather.option import OPEN_K_GRAMMAR
from weather_gym.weather.spec import parse_open_k


def register(sub) -> None:
    p = sub.add_parser(
        "sweep", help="detector mAP vs an effect's k on a fixed rendered set (the study's Figures 3 and 5)",
        description="Measure the shipped detector's mAP@0.5 (and COCO mAP, per-class AP, recall by range) at each k "
                    "of one or more effects, on a fixed COCO evaluation set, each seed a different weather "
                    "realisation. Parallel and resumable (the evaluation runner); writes OUT/curves.csv, "
                    "OUT/curves.png, OUT/curves_recall.png and OUT/sweep.json.",
        formatter_class=OneDefaultFormatter,
    )
    p.add_argument("--weather", action="append", required=True, metavar="SPEC",
                   help=f"effects to sweep, {OPEN_K_GRAMMAR}; repeatable")
    p.add_argument("--k-grid", default="0:1:0.05",
                   help="k values of every effect: START:STOP:STEP (ends included) or K1,K2,...")
    seeds = p.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=int, default=5, help="number of weather realisations per k: seeds 0..N-1")
    seeds.add_argument("--seed-list", default=None, help="explicit seeds, comma-separated (instead of --seeds)")
    p.add_argument("--dataset", type=Path, required=True,
                   help="COCO evaluation set (weather-gym dataset render), e.g. a held-out track with the default look")
    add_detector_args(p, legacy_model=True)
    p.add_argument("--out", type=Path, required=True, help="output folder (curves.csv is resumed, never clobbered)")
    p.add_argument("--no-plot", action="store_true", help="do not draw curves.png")
    add_overwrite_arg(p, help="replace plots or sweep.json in --out that no earlier sweep there wrote "
                              "(curves.csv is always resumed, never replaced)")
    add_runner_args(p)
    p.set_defaults(func=_run)


def sweep_effects(spec: str) -> list[SweepEffect]:
    """The effects of a ``--weather`` spec with k left open, as the sweep's :class:`SweepEffect`.

    Example:
        >>> [e.label for e in sweep_effects("droplets,dim:k:mode=physical")]
        ['droplets', 'dim_physical']
    """
    out = []
    for name, params in parse_open_k(spec):
        text = ",".join(f"{k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in params.items())
        out.append(parse_effect(f"{name}:{text}" if text else name))
    return out


def _run(args) -> int:
    effects = [e for spec in args.weather for e in sweep_effects(spec)]
    try:
        ks = parse_k_range(args.k_grid)
    except InputError as exc:  # its messages name the values as --k
        raise InputError(str(exc).replace("--k ", "--k-grid ", 1)) from None
    seeds = parse_seeds(args.seeds, args.seed_list)
    check_runner_args(args)
    declare_inputs(args.dataset)
    if not args.dataset.exists():
        raise MissingInputError(f"--dataset {args.dataset} not found (render one with `weather-gym dataset render`)")
    detector = detector_spec_from_args(args)
    cells = make_sweep_cells(effects, ks, seeds, args.dataset, detector)  # validates set and detector first
    check_results_path(args.out / CURVE_FILE)
    command = shlex.join(["weather-gym", *sys.argv[1:]]) if "sweep" in sys.argv[1:2] else None
    print(f"{len(cells)} cells ({len(effects)} effect(s) x {len(ks)} k x {len(seeds)} seeds) -> "
          f"{args.out / CURVE_FILE} ({args.backend}, {args.workers} workers)", file=sys.stderr)
    rows = run_sweep(effects, ks, seeds, args.dataset, args.out, model=detector, workers=args.workers,
                     backend=args.backend, progress=not args.no_progress, retry_failed=not args.skip_failed,
                     ray_address=args.ray_address, plot=not args.no_plot, command=command, overwrite=args.overwrite)
    failed = [r for r in rows if r["status"] != "ok"]
    curves = load_curves(args.out / CURVE_FILE, dataset_id=cells[0].dataset_id, model_id=cells[0].model_id)
    print("effect           k      mAP@0.5 mean ± sd   relative")
    for e in effects:
        c = curves.get(e.label)
        if c is None:
            continue
        ideal = c.mean[0] if np.isclose(c.ks[0], 0.0) else float("nan")
        for k, m, s in zip(c.ks, c.mean, c.sd, strict=True):
            print(f"{e.label:<16} {k:<6.3g} {m:.3f} ± {s:.3f}       {m / ideal:.3f}")
    print(f"{len(rows) - len(failed)} ok, {len(failed)} failed; {args.out / CURVE_FILE}"
          + ("" if args.no_plot else f", {args.out / 'curves.png'}"))
    for r in failed[:5]:
        print(f"  failed: {r['effect']} k={r['k']} seed {r['seed']}: {r['error']}", file=sys.stderr)
    return 1 if failed else 0
