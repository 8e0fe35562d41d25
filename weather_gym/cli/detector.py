"""``weather-gym detector train|eval|predict``: the ONNX cone detector.

Examples:
    weather-gym detector train --data data/train --val data/val --epochs 30 --seed 0 --out model.onnx
    weather-gym detector eval data/val
    weather-gym detector eval data/val --weather droplets:0.55 --seed 0
    weather-gym detector eval data/val --weather low_light@2
    weather-gym detector predict frame.png --out annotated.png --weather dim:0.78
    weather-gym detector predict frame.png --json detections.json   # COCO results, as pycocotools' loadRes reads them
    weather-gym detector sweep data/val --weather droplets,dim --k-grid 0,0.55,0.78 --plot docs/img/detections_map_vs_k.png
    weather-gym detector figure data/val --index 40 --out docs/img/detections.png

The second command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['detector', 'eval', 'data/val'])
    >>> args.detector_command, str(args.dataset), args.seed
    ('eval', 'data/val', 0)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from weather_gym.cli._detector_args import add_detector_args, detector_from_args
from weather_gym.cli._seed_arg import seed_arg
from weather_gym.core._io import atomic_write_json, check_output, declare_inputs, write_image
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError, LimitError, MissingDependencyError, MissingInputError
from weather_gym.core.limits import check_image_size
from weather_gym.lab.datasets.coco import load_coco, read_image
from weather_gym.lab.training.detector.plots import (
    STUDY_CLEAN_MAP,
    STUDY_POINTS,
    detections_figure,
    plot_map_vs_k,
    sweep_map_vs_k,
)
from weather_gym.perception.draw import draw_detections
from weather_gym.perception.scoring import coco_results, score_dataset
from weather_gym.weather.option import OPEN_K_GRAMMAR, add_weather_arg, weather_from_arg
from weather_gym.weather.spec import parse_open_k


def register(sub) -> None:
    p = sub.add_parser("detector", help="train, score or run the ONNX cone detector",
                       description="The cone detector: training (needs the 'train' extra: torch, onnx), "
                                   "pycocotools scoring under weather, and single-image prediction.")
    cmds = p.add_subparsers(dest="detector_command", metavar="ACTION", required=True)

    t = cmds.add_parser("train", help="train ConeNet on rendered COCO data and export ONNX")
    t.add_argument("--data", type=Path, action="append", required=True,
                   help="training COCO folder (repeatable): rendered sets or imported recordings (any frame size; "
                        "their ignore regions and ignore masks carry no loss)")
    t.add_argument("--mix", default=None, metavar="W,W,...",
                   help="share of each --data folder in every epoch, in --data order (e.g. 0.7,0.3); "
                        "default: every frame once per epoch")
    t.add_argument("--epoch-frames", type=int, default=None, help="frames per epoch with --mix (default: all frames)")
    t.add_argument("--recipe", default="sim", choices=("sim", "real", "real_robust"),
                   help="augmentation recipe: sim (mild jitter, the first shipped model's), real (wide scale, "
                        "shift, unlabelled clutter, a clear-day camera: exposure to blown-out, tone, noise, JPEG) or "
                        "real_robust (real + under-exposure, blur, strong noise: robust to the weather effects too)")
    t.add_argument("--distractors", type=float, default=None, metavar="P",
                   help="probability of pasting unlabelled clutter into a training crop (default: the recipe's)")
    t.add_argument("--camera-look", type=float, default=None, metavar="P",
                   help="probability of a random real-camera rendition of a crop (default: the recipe's)")
    t.add_argument("--init", type=Path, default=None, metavar="MODEL.onnx",
                   help="start from this ConeNet ONNX model (fine-tuning; its batch norms stay frozen)")
    t.add_argument("--stride", type=int, default=4, choices=(2, 4),
                   help="output grid stride: 4, or 2 to separate cones whose centres are a few pixels apart, such "
                        "as start-line pairs (a stride-2 net can start from a stride-4 --init; default %(default)s)")
    t.add_argument("--hidden-heads", action="store_true",
                   help="add hidden-cone heatmaps, trained on cones whose box touches a nearer cone's (the rear "
                        "cone of a pair): a peak of their own for cones seen behind another (can start from an "
                        "--init without them)")
    t.add_argument("--hidden-boxes", action="store_true",
                   help="with --hidden-heads: the hidden-cone head also regresses the hidden cones' boxes, from every "
                        "cell near their centre (can start from an --init with hidden heads but without boxes)")
    t.add_argument("--blocks", default=None, metavar="B,B,B,B",
                   help="residual blocks at strides 4, 8, 16, 32 (default 1,2,2,1); with --init, a deeper net starts "
                        "as the --init model, each added block as the identity")
    t.add_argument("--stem-blocks", type=int, default=0, metavar="N",
                   help="residual blocks at stride 2, after the stem (default %(default)s)")
    t.add_argument("--tiny-negatives", action="store_true",
                   help="a cone too small to be scored is ignored in its own class only and is a negative for "
                        "the others (default: ignored in every class, so any class may fire on it)")
    t.add_argument("--warmup", type=int, default=200, help="warm-up steps of the learning rate (default %(default)s)")
    t.add_argument("--val", type=Path, default=None, help="validation COCO folder (mAP@0.5 logged every 5 epochs)")
    t.add_argument("--epochs", type=int, default=30)
    t.add_argument("--batch-size", type=int, default=16)
    t.add_argument("--lr", type=float, default=3e-3)
    t.add_argument("--seed", type=seed_arg, default=0)
    t.add_argument("--threads", type=int, default=1, help="torch CPU threads (default %(default)s; 2 only on an idle machine)")
    t.add_argument("--device", default="cpu",
                   help="torch device of the net: cpu, cuda or cuda:N (default %(default)s); the samples are made on the CPU")
    t.add_argument("--workers", type=int, default=0,
                   help="processes that make the training samples (default %(default)s: in the training process); "
                        "the samples do not depend on it")
    t.add_argument("--input-size", type=int, nargs=2, default=(512, 288), metavar=("W", "H"))
    t.add_argument("--crop-size", type=int, nargs=2, default=(320, 192), metavar=("W", "H"),
                   help="train on random crops of this size of the input (multiples of 32; default %(default)s)")
    t.add_argument("--max-steps", type=int, default=None, help="stop after this many optimizer steps")
    t.add_argument("--out", type=Path, required=True, help="ONNX file to write (+ .json sidecar)")
    add_overwrite_arg(t, help="replace an existing --out")
    t.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                   help="continue from the checkpoint of an interrupted run into --out (--no-resume: start afresh)")
    t.set_defaults(func=_train)

    e = cmds.add_parser("eval", help="score the detector on a COCO folder (optionally under weather)")
    e.add_argument("dataset", type=Path)
    add_detector_args(e, legacy_model=True)
    add_weather_arg(e, help="weather applied to every image (default: none)")
    e.add_argument("--seed", type=seed_arg, default=0, help="seed of the weather (default %(default)s)")
    e.add_argument("--limit", type=int, default=None, help="score only the first N images")
    e.add_argument("--threads", type=int, default=2)
    e.add_argument("--json", type=Path, default=None, help="also write the result as JSON here")
    add_overwrite_arg(e, help="replace an existing --json")
    e.set_defaults(func=_eval)

    pr = cmds.add_parser("predict", help="detect cones in one image: draw them, write them as COCO results, or both")
    pr.add_argument("image", type=Path)
    pr.add_argument("--out", type=Path, default=None, help="annotated PNG to write")
    pr.add_argument("--json", type=Path, default=None, metavar="PATH.json",
                    help="the detections in COCO's results format (image_id, category_id = class index + 1, "
                         "bbox [x, y, w, h] in pixels, score), as pycocotools' loadRes reads them")
    pr.add_argument("--image-id", type=int, default=1, help="image_id written in --json (default %(default)s)")
    add_detector_args(pr, legacy_model=True)
    add_weather_arg(pr, help="weather applied to the image first (default: none)")
    pr.add_argument("--seed", type=seed_arg, default=0)
    pr.add_argument("--threshold", type=float, default=None, help="score threshold (default: the model's)")
    add_overwrite_arg(pr, help="replace an existing --out")
    pr.set_defaults(func=_predict)

    sw = cmds.add_parser("sweep", help="mAP versus k for droplets and dim (the study's Figures 3 and 5)")
    sw.add_argument("dataset", type=Path)
    add_detector_args(sw, legacy_model=True)
    sw.add_argument("--weather", default="droplets,dim", metavar="SPEC",
                    help=f"effects to sweep, {OPEN_K_GRAMMAR} (default %(default)s)")
    sw.add_argument("--k-grid", default="0,0.2,0.4,0.55,0.7,0.78,0.9", metavar="K1,K2,...",
                    help="the k values of every --weather effect, comma-separated (default %(default)s)")
    sw.add_argument("--seed", type=seed_arg, default=0)
    sw.add_argument("--limit", type=int, default=None)
    sw.add_argument("--threads", type=int, default=2)
    sw.add_argument("--plot", type=Path, default=None, help="PNG plot to write")
    sw.add_argument("--json", type=Path, default=None, help="JSON of the sweep to write")
    add_overwrite_arg(sw, help="replace existing --plot / --json files")
    sw.set_defaults(func=_sweep)

    fg = cmds.add_parser("figure", help="one frame with detections: clean | droplets 0.55 | dim 0.78")
    fg.add_argument("dataset", type=Path)
    fg.add_argument("--index", type=int, default=0, help="image index in the dataset")
    add_detector_args(fg, legacy_model=True)
    fg.add_argument("--seed", type=seed_arg, default=0)
    fg.add_argument("--out", type=Path, required=True, help="PNG to write")
    add_overwrite_arg(fg, help="replace an existing --out")
    fg.set_defaults(func=_figure)


def _train(args) -> int:
    try:
        from weather_gym.lab.training.detector.train import TrainConfig, train_detector
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise MissingDependencyError(f"training needs the 'train' extra (torch, onnx): {exc}") from None
    declare_inputs(*args.data, args.val, args.init)
    check_output(args.out, overwrite=args.overwrite, suffixes=(".onnx",), what="--out")
    check_output(args.out.with_suffix(".json"), overwrite=args.overwrite, what="model sidecar")
    mix = _parse_mix(args.mix, len(args.data))
    if args.epoch_frames is not None and mix is None:
        raise InputError("--epoch-frames needs --mix")
    if args.init is not None and not args.init.is_file():
        raise MissingInputError(f"--init {args.init} does not exist")
    extra = {k: v for k, v in (("distractors", args.distractors), ("camera", args.camera_look)) if v is not None}
    cfg = TrainConfig.recipe(args.recipe, input_size=tuple(args.input_size), epochs=args.epochs,
                             batch_size=args.batch_size, lr=args.lr, seed=args.seed, threads=args.threads,
                             max_steps=args.max_steps, mix=mix, epoch_frames=args.epoch_frames,
                             warmup_iters=args.warmup, crop_size=tuple(args.crop_size),
                             init=None if args.init is None else str(args.init), stride=args.stride, hidden=args.hidden_heads,
                             hidden_boxes=args.hidden_boxes, stem_blocks=args.stem_blocks,
                             tiny_negatives=args.tiny_negatives,
                             **({} if args.blocks is None else {"blocks": _parse_blocks(args.blocks)}),
                             device=args.device, workers=args.workers, **extra)
    result = train_detector(args.data, args.out, cfg, val=args.val, resume=args.resume,
                            overwrite=args.overwrite)
    print(f"wrote {result['model']} ({result['steps']} steps, {result['train_time_s']:.0f} s)")
    return 0


def _parse_blocks(spec: str) -> tuple[int, int, int, int]:
    try:  # the count and signs are checked by TrainConfig
        return tuple(int(v) for v in spec.split(","))  # type: ignore[return-value]  # TrainConfig checks there are four
    except ValueError:
        raise InputError(f"--blocks must be 4 comma-separated whole numbers (strides 4, 8, 16, 32), got {spec!r}") from None


def _parse_mix(spec: str | None, n: int) -> tuple[float, ...] | None:
    if spec is None:
        return None
    try:
        shares = tuple(float(v) for v in spec.split(","))
    except ValueError:
        raise InputError(f"--mix must be comma-separated numbers, one per --data, got {spec!r}") from None
    if len(shares) != n:
        raise InputError(f"--mix gives {len(shares)} shares for {n} --data folders: give one per folder")
    if any(not (v >= 0) or v == float("inf") for v in shares) or sum(shares) <= 0:
        raise InputError(f"--mix shares must be finite, >= 0 and not all 0, got {spec!r}")
    return shares


def _eval(args) -> int:
    declare_inputs(args.dataset)
    _check_limit(args.limit)
    _check_threads(args.threads)
    weather = weather_from_arg(args.weather)  # a bad spec fails now, not after loading everything
    if args.json is not None:
        check_output(args.json, overwrite=args.overwrite, suffixes=(".json",), what="--json")
    ds = load_coco(args.dataset)
    _check_not_empty(ds)
    det = detector_from_args(args, threads=args.threads)
    result = score_dataset(ds, det, weather, seed=args.seed, limit=args.limit, progress=True)
    label = "clear" if weather is None else args.weather
    print(f"{args.dataset} | {det.name} | weather: {label} | seed {args.seed}")
    print(result.table())
    if args.json is not None:
        atomic_write_json(args.json, {"dataset": str(args.dataset), "detector": det.name, "weather": label,
                                      **result.to_dict()}, indent=2, default=str, overwrite=args.overwrite)
    return 0


def _check_limit(limit: int | None) -> None:
    if limit is not None and limit < 1:
        raise InputError(f"--limit must be >= 1 (images to score), got {limit}")


def _check_threads(threads: int) -> None:
    most = 4 * (os.cpu_count() or 1)
    if not 1 <= threads <= most:
        raise LimitError(f"--threads must be in 1..{most} (4 per CPU core), got {threads}")


def _check_not_empty(ds) -> None:
    if len(ds) == 0:
        raise InputError(f"{ds.annotations_path} lists no images: nothing to score")


def _predict(args) -> int:
    declare_inputs(args.image)
    if args.out is None and args.json is None:
        raise InputError("detector predict writes --out (an annotated picture), --json (COCO results) or both; "
                         "give at least one")
    if args.out is not None:
        check_output(args.out, overwrite=args.overwrite, suffixes=(".png", ".jpg", ".jpeg"), what="--out")
    if args.json is not None:
        check_output(args.json, overwrite=args.overwrite, suffixes=(".json",), what="--json")
        if args.out is not None and args.json.resolve() == args.out.resolve():
            raise InputError("--out and --json must be different files")
    if args.threshold is not None and not 0 <= args.threshold <= 1:
        raise InputError(f"--threshold must be a score in [0, 1], got {args.threshold}")
    image = read_image(args.image)
    check_image_size(image.shape, what=str(args.image))
    weather = weather_from_arg(args.weather)
    if weather is not None:
        image = weather.start(args.seed)(image, rng=np.random.default_rng(args.seed))
    if args.threshold is not None:
        args.detector_threshold = args.threshold
    det = detector_from_args(args)
    d = det(image)
    written = []
    if args.out is not None:
        write_image(args.out, draw_detections(image, d), overwrite=args.overwrite)
        written.append(str(args.out))
    if args.json is not None:
        results = coco_results(d.to_dict(), args.image_id)
        atomic_write_json(args.json, results, indent=1, overwrite=args.overwrite)
        written.append(str(args.json))
    print(f"{len(d)} cones -> {', '.join(written)}")
    return 0


def _sweep(args) -> int:
    declare_inputs(args.dataset)
    try:
        ks = sorted({float(v) for v in args.k_grid.split(",")})
    except ValueError:
        raise InputError(f"--k-grid must be comma-separated numbers, got {args.k_grid!r}") from None
    if any(not 0 <= k <= 1 for k in ks):
        raise InputError(f"--k-grid must lie in [0, 1], got {ks}")
    effects = []
    for name, params in parse_open_k(args.weather):
        if params:
            raise InputError(f"--weather {args.weather!r}: detector sweep varies plain effects (NAME,NAME...); "
                             f"for {name} with parameters use `weather-gym sweep`")
        effects.append(name)
    _check_limit(args.limit)
    _check_threads(args.threads)
    if args.plot is not None:
        check_output(args.plot, overwrite=args.overwrite, suffixes=(".png",), what="--plot")
    if args.json is not None:
        check_output(args.json, overwrite=args.overwrite, suffixes=(".json",), what="--json")
    ds = load_coco(args.dataset, cache_images=True)
    _check_not_empty(ds)
    det = detector_from_args(args, threads=args.threads)
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
        plot_map_vs_k(sweep, args.plot, title=f"{args.dataset.name}: mAP@0.5 vs k (seed {args.seed})",
                      overwrite=args.overwrite)
        print(f"wrote {args.plot}")
    if args.json is not None:
        atomic_write_json(args.json, sweep, indent=2, overwrite=args.overwrite)
    return 0


def _figure(args) -> int:
    declare_inputs(args.dataset)
    check_output(args.out, overwrite=args.overwrite, suffixes=(".png",), what="--out")
    ds = load_coco(args.dataset)
    _check_not_empty(ds)
    if not 0 <= args.index < len(ds):
        raise InputError(f"--index must be in 0..{len(ds) - 1}, got {args.index}")
    rec = ds.record(args.index)
    state = {"speed": float(rec.get("speed", 0.0)), "yaw_rate": float(rec.get("yaw_rate", 0.0))}
    out = detections_figure(ds.image(args.index), detector_from_args(args), args.out, depth=ds.depth(args.index),
                            state=state, seed=args.seed, overwrite=args.overwrite)
    print(f"wrote {out}")
    return 0
