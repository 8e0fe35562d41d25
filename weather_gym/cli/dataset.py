"""``weather-gym dataset render|info``: COCO datasets of rendered cone frames.

Examples:
    weather-gym dataset render --track small_track --track random:3 --frames 500 --out data/train --randomize
    weather-gym dataset render --track peanut --frames 300 --out data/val --seed 101
    weather-gym dataset info data/val
"""

from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("dataset", help="render or inspect COCO datasets of cone frames",
                       description="Drive the ground-truth driver around tracks and write COCO datasets "
                                   "(images/, depth/, annotations.json).")
    cmds = p.add_subparsers(dest="dataset_command", metavar="ACTION", required=True)
    r = cmds.add_parser("render", help="render frames with ground-truth boxes into a COCO folder")
    r.add_argument("--track", action="append", required=True,
                   help="track name or 'random:SEED'; repeat for several tracks (frames are split evenly)")
    r.add_argument("--frames", type=int, required=True, help="number of frames to write")
    r.add_argument("--out", type=Path, required=True, help="output folder (never overwritten without --overwrite)")
    r.add_argument("--seed", type=int, default=0, help="master seed (default %(default)s): same seed, same bytes")
    r.add_argument("--randomize", action="store_true",
                   help="random look per episode: light direction/colour, ground and sky, cone shades, camera jitter")
    r.add_argument("--every", type=int, default=3, help="save one frame every N env steps (default %(default)s)")
    r.add_argument("--frames-per-episode", type=int, default=20,
                   help="frames per episode before a new start point/look (default %(default)s)")
    r.add_argument("--width", type=int, default=None, help="camera width in pixels (default 672)")
    r.add_argument("--height", type=int, default=None, help="camera height in pixels (default 376)")
    r.add_argument("--resume", action="store_true", help="continue an interrupted render in --out")
    r.add_argument("--overwrite", action="store_true", help="replace an existing dataset in --out")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=_render)
    i = cmds.add_parser("info", help="summary of a COCO dataset folder (validates it)")
    i.add_argument("dir", type=Path)
    i.set_defaults(func=_info)


def _render(args) -> int:
    from weather_gym.camera import CameraConfig
    from weather_gym.datasets.render import render_dataset

    cam = CameraConfig()
    if args.width or args.height:
        cam = cam.scaled(args.width or cam.width, args.height or cam.height)
    path = render_dataset(args.out, tracks=args.track, frames=args.frames, seed=args.seed, randomize=args.randomize,
                          camera=cam, every=args.every, frames_per_episode=args.frames_per_episode,
                          progress=not args.quiet, overwrite=args.overwrite, resume=args.resume)
    print(f"wrote {path}")
    return 0


def _info(args) -> int:
    from collections import Counter

    import numpy as np

    from weather_gym.cone_spec import CONE_CLASSES
    from weather_gym.datasets.coco import load_coco
    from weather_gym.perception.labels import MIN_BOX_HEIGHT_PX

    ds = load_coco(args.dir)
    anns = ds.data["annotations"]
    tracks = Counter(im.get("track", "?") for im in ds.images)
    heights = np.array([a["bbox"][3] for a in anns]) if anns else np.zeros(0)
    crowd = sum(int(a.get("iscrowd", 0)) for a in anns)
    per_class = Counter(CONE_CLASSES[a["category_id"] - 1] for a in anns if not a.get("iscrowd", 0))
    print(f"{args.dir}: {len(ds)} images, {len(anns)} cones ({crowd} tiny: box height < {MIN_BOX_HEIGHT_PX:g} px, ignored)")
    print("tracks: " + ", ".join(f"{t} ({n})" for t, n in sorted(tracks.items())))
    print("scored cones per class: " + ", ".join(f"{c} {per_class.get(c, 0)}" for c in CONE_CLASSES))
    if heights.size:
        q = np.percentile(heights, [10, 50, 90])
        print(f"box height px: p10 {q[0]:.1f}, median {q[1]:.1f}, p90 {q[2]:.1f}")
    return 0
