"""``weather-gym detector train|eval|predict``: the ONNX cone detector.

Examples:
    weather-gym detector train --data data/train --val data/val --epochs 30 --seed 0 --out model.onnx
    weather-gym detector eval data/val
    weather-gym detector eval data/val --effect droplets --k 0.55 --seed 0
    weather-gym detector eval data/val --weather "dim:0.78"
    weather-gym detector predict frame.png --out annotated.png --effect dim --k 0.78
    weather-gym detector sweep data/val --plot docs/img/detections_map_vs_k.png
    weather-gym detector figure data/val --index 40 --out docs/img/detections.png
"""

from __future__ import annotations

import json
from pathlib import Path

from weather_gym.cli._detector_args import add_detector_args, detector_from_args


def register(sub) -> None:
    p = sub.add_parser("detector", help="train, score or run the ONNX cone detector",
                       description="The cone detector: training (needs the 'train' extra: torch, onnx), "
                                   "pycocotools scoring under weather, and single-image prediction.")
    cmds = p.add_subparsers(dest="detector_command", metavar="ACTION", required=True)

    t = cmds.add_parser("train", help="train ConeNet on rendered COCO data and export ONNX")
    t.add_argument("--data", type=Path, action="append", required=True, help="training COCO folder (repeatable)")
    t.add_argument("--val", type=Path, default=None, help="validation COCO folder (mAP@0.5 logged every 5 epochs)")
    t.add_argument("--epochs", type=int, default=30)
    t.add_argument("--batch-size", type=int, default=16)
    t.add_argument("--lr", type=float, default=3e-3)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--threads", type=int, default=1, help="torch CPU threads (default %(default)s; 2 only on an idle machine)")
    t.add_argument("--input-size", type=int, nargs=2, default=(512, 288), metavar=("W", "H"))
    t.add_argument("--max-steps", type=int, default=None, help="stop after this many optimizer steps")
    t.add_argument("--out", type=Path, required=True, help="ONNX file to write (+ .json sidecar)")
    t.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    t.add_argument("--no-resume", action="store_true", help="ignore a checkpoint from an interrupted run")
    t.set_defaults(func=_train)

    e = cmds.add_parser("eval", help="score the detector on a COCO folder (optionally under weather)")
    e.add_argument("dataset", type=Path)
    add_detector_args(e, legacy_model=True)
    e.add_argument("--effect", default=None, help="weather effect name (e.g. droplets, dim)")
    e.add_argument("--k", type=float, default=None, help="severity of --effect in [0, 1]")
    e.add_argument("--weather", default=None, help="any weather spec instead of --effect/--k, e.g. 'droplets:0.55,dim:0.3'")
    e.add_argument("--seed", type=int, default=0, help="seed of the weather (default %(default)s)")
    e.add_argument("--limit", type=int, default=None, help="score only the first N images")
    e.add_argument("--threads", type=int, default=2)
    e.add_argument("--json", type=Path, default=None, help="also write the result as JSON here")
    e.set_defaults(func=_eval)

    pr = cmds.add_parser("predict", help="detect cones in one image and draw them")
    pr.add_argument("image", type=Path)
    pr.add_argument("--out", type=Path, required=True, help="annotated PNG to write")
    add_detector_args(pr, legacy_model=True)
    pr.add_argument("--effect", default=None)
    pr.add_argument("--k", type=float, default=None)
    pr.add_argument("--seed", type=int, default=0)
    pr.add_argument("--threshold", type=float, default=None, help="score threshold (default: the model's)")
    pr.add_argument("--force", action="store_true", help="overwrite --out")
    pr.set_defaults(func=_predict)

    sw = cmds.add_parser("sweep", help="mAP versus k for droplets and dim (the study's Figures 3 and 5)")
    sw.add_argument("dataset", type=Path)
    add_detector_args(sw, legacy_model=True)
    sw.add_argument("--ks", default="0,0.2,0.4,0.55,0.7,0.78,0.9", help="comma-separated k values")
    sw.add_argument("--effects", default="droplets,dim")
    sw.add_argument("--seed", type=int, default=0)
    sw.add_argument("--limit", type=int, default=None)
    sw.add_argument("--threads", type=int, default=2)
    sw.add_argument("--plot", type=Path, default=None, help="PNG plot to write")
    sw.add_argument("--json", type=Path, default=None, help="JSON of the sweep to write")
    sw.set_defaults(func=_sweep)

    fg = cmds.add_parser("figure", help="one frame with detections: clean | droplets 0.55 | dim 0.78")
    fg.add_argument("dataset", type=Path)
    fg.add_argument("--index", type=int, default=0, help="image index in the dataset")
    add_detector_args(fg, legacy_model=True)
    fg.add_argument("--seed", type=int, default=0)
    fg.add_argument("--out", type=Path, required=True)
    fg.set_defaults(func=_figure)


def _weather(args):
    if getattr(args, "weather", None):
        if args.effect is not None:
            raise ValueError("give either --weather or --effect/--k, not both")
        return args.weather
    if args.effect is None:
        if args.k is not None:
            raise ValueError("--k needs --effect")
        return None
    from weather_gym.weather import make

    if args.k is None:
        raise ValueError(f"--effect {args.effect} needs --k (severity in [0, 1])")
    return make(args.effect, k=args.k)


def _train(args) -> int:
    try:
        from weather_gym.perception.train import TrainConfig, train_detector
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ValueError(f"training needs the 'train' extra (torch, onnx): {exc}") from None
    if args.out.exists() and not args.overwrite:
        raise FileExistsError(f"{args.out} already exists; pass --overwrite to replace it")
    cfg = TrainConfig(input_size=tuple(args.input_size), epochs=args.epochs, batch_size=args.batch_size, lr=args.lr,
                      seed=args.seed, threads=args.threads, max_steps=args.max_steps)
    result = train_detector(args.data, args.out, cfg, val=args.val, resume=not args.no_resume)
    print(f"wrote {result['model']} ({result['steps']} steps, {result['train_time_s']:.0f} s)")
    return 0


def _eval(args) -> int:
    from weather_gym._io import atomic_write
    from weather_gym.datasets.coco import load_coco
    from weather_gym.perception.scoring import score_dataset

    ds = load_coco(args.dataset)
    det = detector_from_args(args, threads=args.threads)
    weather = _weather(args)
    result = score_dataset(ds, det, weather, seed=args.seed, limit=args.limit, progress=True)
    label = "clear" if weather is None else (args.weather or f"{args.effect} k={args.k}")
    print(f"{args.dataset} | {det.name} | weather: {label} | seed {args.seed}")
    print(result.table())
    if args.json is not None:
        atomic_write(args.json, json.dumps({"dataset": str(args.dataset), "detector": det.name, "weather": label,
                                            **result.to_dict()}, indent=2, default=str))
    return 0


def _predict(args) -> int:
    import cv2
    import numpy as np

    from weather_gym.datasets.coco import read_image
    from weather_gym.perception.draw import draw_detections

    if args.out.exists() and not args.force:
        raise FileExistsError(f"{args.out} already exists; pass --force to overwrite it")
    image = read_image(args.image)
    weather = _weather(args)
    if weather is not None:
        from weather_gym.weather import parse_weather

        eff = parse_weather(weather)
        eff.reset(args.seed)
        image = eff(image, rng=np.random.default_rng(args.seed))
    if args.threshold is not None:
        args.detector_threshold = args.threshold
    det = detector_from_args(args)
    d = det(image)
    if not cv2.imwrite(str(args.out), cv2.cvtColor(draw_detections(image, d), cv2.COLOR_RGB2BGR)):
        raise ValueError(f"could not write {args.out}")
    print(f"{len(d)} cones -> {args.out}")
    return 0


def _sweep(args) -> int:
    from weather_gym.datasets.coco import load_coco
    from weather_gym.perception.report import STUDY_CLEAN_MAP, STUDY_POINTS, plot_map_vs_k, sweep_map_vs_k

    try:
        ks = sorted({float(v) for v in args.ks.split(",")})
    except ValueError:
        raise ValueError(f"--ks must be comma-separated numbers, got {args.ks!r}") from None
    if any(not 0 <= k <= 1 for k in ks):
        raise ValueError(f"--ks must lie in [0, 1], got {ks}")
    ds = load_coco(args.dataset, cache_images=True)
    det = detector_from_args(args, threads=args.threads)
    effects = [e.strip() for e in args.effects.split(",") if e.strip()]
    sweep = sweep_map_vs_k(ds, det, ks, effects, seed=args.seed, limit=args.limit)
    print(f"{args.dataset} | {det.name} | seed {args.seed}")
    print("effect     k      mAP@0.5  mAP@.5:.95  relative   study (relative)")
    for e, rows in sweep.items():
        clean = next((r["map50"] for r in rows if r["k"] == 0), float("nan"))
        for r in rows:
            study = ""
            if e in STUDY_POINTS and abs(STUDY_POINTS[e][0] - r["k"]) < 1e-9:
                m = STUDY_POINTS[e][1]
                study = f"{STUDY_CLEAN_MAP}->{m} ({m / STUDY_CLEAN_MAP:.3f})"
            print(f"{e:<10} {r['k']:<6.2f} {r['map50']:<8.3f} {r['map']:<11.3f} {r['map50'] / clean:<10.3f} {study}")
    if args.plot is not None:
        plot_map_vs_k(sweep, args.plot, title=f"{args.dataset.name}: mAP@0.5 vs k (seed {args.seed})")
        print(f"wrote {args.plot}")
    if args.json is not None:
        with open(args.json, "w") as f:
            json.dump(sweep, f, indent=2)
    return 0


def _figure(args) -> int:
    from weather_gym.datasets.coco import load_coco
    from weather_gym.perception.report import detections_figure

    ds = load_coco(args.dataset)
    if not 0 <= args.index < len(ds):
        raise ValueError(f"--index must be in 0..{len(ds) - 1}, got {args.index}")
    rec = ds.record(args.index)
    state = {"speed": float(rec.get("speed", 0.0)), "yaw_rate": float(rec.get("yaw_rate", 0.0))}
    out = detections_figure(ds.image(args.index), detector_from_args(args), args.out, depth=ds.depth(args.index),
                            state=state, seed=args.seed)
    print(f"wrote {out}")
    return 0
