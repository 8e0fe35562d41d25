"""``weather-gym dataset render|import|mask|merge|info``: COCO datasets of cone frames, rendered or imported.

Examples:
    weather-gym dataset render --track small_track --track random:3 --frames 500 --out data/train --randomize
    weather-gym dataset render --track peanut --frames 300 --out data/val --seed 101
    weather-gym dataset import kitti recordings/estoril --out data/real --intrinsics 900.9,900.1,506.4,358.0 \
        --condition clear
    weather-gym dataset mask data/real --out ego_mask.png --preview ego_preview.png   # propose, then edit
    weather-gym dataset mask data/real --set ego_mask.png                             # store with the dataset
    weather-gym dataset info data/real
    weather-gym dataset merge data/peanut data/hairpin data/realistic --out data/pool   # one set of many tracks

The last command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['dataset', 'merge', 'data/peanut', 'data/hairpin', 'data/realistic', '--out', 'data/pool'])
    >>> args.dataset_command, [str(p) for p in args.src], str(args.out)
    ('merge', ['data/peanut', 'data/hairpin', 'data/realistic'], 'data/pool')
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.cli._camera_isp_arg import add_camera_model_arg, camera_model_arg
from weather_gym.cli._detector_args import add_detector_args, detector_from_args
from weather_gym.cli._seed_arg import seed_arg
from weather_gym.core._io import check_output, declare_inputs, write_image
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.frame_position import EDGE_RADIUS, edge_share
from weather_gym.lab.datasets.import_rosbag import import_rosbag
from weather_gym.lab.datasets.importers import DEFAULT_CLASSES, FORMATS, import_dataset
from weather_gym.lab.datasets.masks import mask_preview, propose_mask, set_dataset_mask, write_mask
from weather_gym.lab.datasets.merge import merge_coco
from weather_gym.lab.datasets.render import render_dataset
from weather_gym.perception.ignore import inside_mask
from weather_gym.perception.labels import MIN_BOX_HEIGHT_PX
from weather_gym.perception.scoring import small_rule
from weather_gym.ros.camera import Window
from weather_gym.sim.randomize import RandomizeRanges


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
    r.add_argument("--seed", type=seed_arg, default=0, help="master seed (default %(default)s): same seed, same bytes")
    r.add_argument("--randomize", action="store_true",
                   help="domain randomisation per episode (realistic world unless --scene plain: then the plain world's): light, "
                        "ground/sky/clutter textures and colours, distractors, ego car, camera pose/FOV, camera "
                        "model (exposure, white balance, distortion, noise, JPEG); see docs/world.md")
    r.add_argument("--scene", choices=("auto", "plain", "realistic"), default="auto",
                   help="world to render: plain (the default world) or realistic (FS-striped cones, clutter, "
                        "ego car); auto (default) = realistic with --randomize, else plain")
    add_camera_model_arg(r, "realistic, the env's default camera",
                         "the camera's finishing stage: realistic, ideal (off: the study's ideal camera, as plain-world "
                         "datasets had before the camera model became the default) or a TOML file of CameraModel "
                         "fields; a randomised realistic render draws its own per episode")
    r.add_argument("--randomize-ranges", type=Path, default=None, metavar="FILE.toml",
                   help="TOML file of randomisation ranges (key = [low, high]; keys as in RandomizeRanges)")
    r.add_argument("--randomize-set", action="append", default=[], metavar="KEY=LOW,HIGH",
                   help="override one randomisation range (repeatable), e.g. exposure_ev=-1,2.5")
    r.add_argument("--every", type=int, default=3, help="save one frame every N env steps (default %(default)s)")
    r.add_argument("--frames-per-episode", type=int, default=20,
                   help="frames per episode before a new start point/look (default %(default)s)")
    r.add_argument("--start-window", default=None, metavar="LOW,HIGH",
                   help="draw start points LOW..HIGH metres of arc length around the start line (negative: before "
                        "it), e.g. -35,-3 for frames approaching the start line; default: anywhere on the track")
    r.add_argument("--width", type=int, default=None, help="camera width in pixels (default 672)")
    r.add_argument("--height", type=int, default=None, help="camera height in pixels (default 376)")
    r.add_argument("--jpeg-quality", type=int, default=None, metavar="Q",
                   help="store the frames as JPEG of quality Q (1-100) instead of PNG: 4-7x smaller, e.g. to move "
                        "a training set to a GPU machine (default: PNG, lossless)")
    r.add_argument("--shadows", choices=("on", "off"), default=None,
                   help="PyBullet's shadow map (SimConfig.shadows): off renders EGL frames without it (faster; "
                        "the objects lose their shaded sides, and the presets are calibrated with it), on gives "
                        "TinyRenderer shadows too; default: the renderer's own way")
    r.add_argument("--resume", action="store_true", help="continue an interrupted render in --out")
    r.add_argument("--overwrite", action="store_true", help="replace an existing dataset in --out")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=_render)
    i = cmds.add_parser("info", help="summary of a COCO dataset folder (validates it)")
    i.add_argument("dir", type=Path)
    add_detector_args(i, what="the too-small rule is stated at this detector's input scale")
    i.set_defaults(func=_info)


    im = cmds.add_parser("import", help="import labelled frames (KITTI, YOLO txt, COCO, Supervisely/FSOCO) or a ROS "
                                        "bag's camera topic into a COCO folder",
                         description="Read a folder of frames and labels, validate it, copy the frames into "
                                     "OUT/images/ and write OUT/annotations.json (nothing outside --out is written; "
                                     "nothing is read through a link that leads out of SRC). See docs/real_data.md.")
    im.add_argument("format", choices=(*FORMATS, "rosbag"), help="label format of SRC, or rosbag (docs/ros.md)")
    im.add_argument("src", type=Path, help="source folder (images/ + labels/; YOLO also images with their .txt beside "
                                           "them; a COCO JSON beside the images; a Supervisely project with meta.json); "
                                           "rosbag: a rosbag2 folder, .mcap or .db3 file, or a ROS 1 .bag")
    im.add_argument("--out", type=Path, required=True, help="new dataset folder (never overwritten without --overwrite)")
    im.add_argument("--classes", default=None, metavar="SRC=TARGET,...",
                    help="class map, TARGET in blue, yellow, orange, big_orange, ignore (ignore regions); '*=ignore' "
                         f"maps every class not named; default {DEFAULT_CLASSES}")
    im.add_argument("--condition", default=None,
                    help="condition of every frame: clear, or a weather condition (droplets, low_light) with --severity")
    im.add_argument("--severity", type=int, default=None, help="severity 1-4 of --condition")
    im.add_argument("--intrinsics", default=None, metavar="FX,FY,CX,CY",
                    help="camera intrinsics in pixels at the image size (else from KITTI calib/ files, else unknown)")
    im.add_argument("--mask", type=Path, default=None, help="ignore-mask PNG (white = ignored) to store with the dataset")
    im.add_argument("--annotations", type=Path, default=None, help="COCO: the JSON file (default: the only *.json in SRC)")
    im.add_argument("--no-project-3d", action="store_true",
                    help="KITTI: leave 3D-only cones out entirely instead of projecting them into ignore regions")
    im.add_argument("--location-frame", default="auto", choices=("auto", "camera", "vehicle", "none"),
                    help="KITTI: frame of the 3D locations used for cone range (default: recognised from the boxes)")
    ros = im.add_argument_group("rosbag (frames are imported without labels: docs/ros.md)")
    ros.add_argument("--topic", default=None, help="the camera topic, sensor_msgs/Image or CompressedImage (default: "
                                                   "the bag's only image topic)")
    ros.add_argument("--camera-info", default=None, metavar="TOPIC",
                     help="the CameraInfo topic giving the intrinsics (default: the one beside --topic, e.g. "
                          "/cam/camera_info for /cam/image_raw; '' for none)")
    ros.add_argument("--every", type=int, default=1, help="keep every Nth frame (default %(default)s)")
    ros.add_argument("--start", type=float, default=None, metavar="S",
                     help="first frame at S seconds after the bag's first message (default: the start)")
    ros.add_argument("--end", type=float, default=None, metavar="S", help="frames before S seconds (default: the end)")
    add_overwrite_arg(im, help="replace an existing dataset, or an interrupted import, in --out")
    im.add_argument("--resume", action="store_true",
                    help="continue an interrupted import in --out (same SRC and settings, else refused)")
    im.add_argument("--quiet", action="store_true", help="no progress bar")
    add_detector_args(im, what="the too-small rule is stated at this detector's input scale")
    im.set_defaults(func=_import)

    m = cmds.add_parser("mask", help="propose an ignore mask (the ego vehicle) from the frames, or store one",
                        description="Without --set: propose an ignore mask from the frames themselves (pixels that "
                                    "stay the same while the scene moves, touching the bottom of the frame) and write "
                                    "it as a PNG to --out for you to check and edit (white = ignored). With --set: "
                                    "store a mask PNG with the dataset (dataset-wide, or for one --frame).")
    m.add_argument("dir", type=Path, help="dataset folder")
    what = m.add_mutually_exclusive_group(required=True)
    what.add_argument("--out", type=Path, help="write the proposed mask PNG here (nothing else is written)")
    what.add_argument("--set", type=Path, metavar="MASK.png", help="store this mask PNG with the dataset")
    m.add_argument("--preview", type=Path, default=None, help="with --out: also write a frame with the mask drawn on it")
    m.add_argument("--frame", default=None, help="with --set: the image file_name the mask is for (default: all frames)")
    m.add_argument("--max-frames", type=int, default=60, help="frames used for the proposal, evenly spaced (default %(default)s)")
    add_overwrite_arg(m, help="replace an existing mask file (--out, --preview, or the dataset's mask with --set)")
    m.set_defaults(func=_mask)

    mg = cmds.add_parser("merge", help="pool several COCO folders into one (e.g. a calibration set of many tracks and worlds)",
                         description="Copy the frames of every SRC into OUT (prefixed s0_, s1_, ...), renumber the ids "
                                     "and write OUT/annotations.json last; the sources must share the cone classes and "
                                     "the too-small rule. OUT's info.sources records what it pools.")
    mg.add_argument("src", type=Path, nargs="+", help="source dataset folders (at least two)")
    mg.add_argument("--out", type=Path, required=True, help="new dataset folder (never overwritten without --overwrite)")
    add_overwrite_arg(mg, help="replace an existing dataset in --out")
    mg.set_defaults(func=_merge)


def _render(args) -> int:
    declare_inputs(args.randomize_ranges)
    cam = CameraConfig()
    if args.width or args.height:
        cam = cam.scaled(args.width or cam.width, args.height or cam.height)
    ranges = RandomizeRanges.from_toml(args.randomize_ranges) if args.randomize_ranges else RandomizeRanges()
    sets = {}
    for item in args.randomize_set:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise InputError(f"--randomize-set expects KEY=LOW,HIGH (e.g. exposure_ev=-1,2), got {item!r}")
        sets[key.strip()] = value
    ranges = ranges.override(sets)
    if (args.randomize_ranges or sets) and not args.randomize:
        raise InputError("--randomize-ranges / --randomize-set need --randomize")
    scene = ("realistic" if args.randomize else "plain") if args.scene == "auto" else args.scene
    model = camera_model_arg(args.camera_model)  # None: the env's default
    if scene == "realistic" and args.randomize and args.camera_model is not None:
        raise InputError("--camera-model: a randomised realistic render draws its camera model per episode "
                         "(ranges: --randomize-set); leave --camera-model out")
    window = None
    if args.start_window is not None:
        parts = args.start_window.split(",")
        try:
            window = tuple(float(v) for v in parts)
        except ValueError:
            window = ()
        if len(window) != 2:
            raise InputError(f"--start-window expects LOW,HIGH in metres (e.g. -35,-3), got {args.start_window!r}")
    path = render_dataset(args.out, tracks=args.track, frames=args.frames, seed=args.seed, randomize=args.randomize,
                          camera=cam, every=args.every, frames_per_episode=args.frames_per_episode,
                          progress=not args.quiet, overwrite=args.overwrite, resume=args.resume, scene=scene,
                          ranges=ranges, start_window=window, camera_model=model, jpeg_quality=args.jpeg_quality,  # type: ignore[arg-type]  # window: 2 numbers, checked
                          shadows=None if args.shadows is None else args.shadows == "on")
    print(f"wrote {path}")
    return 0


def _merge(args) -> int:
    declare_inputs(*args.src)
    out = merge_coco(args.src, args.out, overwrite=args.overwrite)
    ds = load_coco(out)
    print(f"wrote {out / 'annotations.json'}: {len(ds)} frames from {len(args.src)} datasets "
          f"({', '.join(str(s['images']) for s in ds.info['sources'])})")
    return 0


def _info(args) -> int:
    ds = load_coco(args.dir)
    anns = ds.data["annotations"]
    info = ds.info
    sizes = Counter(f"{im['width']}x{im['height']}" for im in ds.images)
    det = detector_from_args(args, required=False)
    sr = small_rule(ds, det)
    if sr is not None:
        rule, min_h = sr.describe(), sr.min_height_px
    else:  # frames of several sizes: the flags stored with the dataset
        min_h = None
        rule = (info.get("too_small") or {}).get("rule") or (
            f"box height < {info.get('min_box_height_px', MIN_BOX_HEIGHT_PX):g} px, as stored")
    masked = 0
    for i in range(len(ds)) if ds.has_ignore_mask else ():
        g = ds.gt(i)
        masked += int((inside_mask(g.get("ignore_mask"), g["boxes"]) & ~g["ignore"]).sum())
    regions = [a for a in anns if a.get("ignore")]

    def is_small(a: dict) -> bool:
        return bool(a.get("iscrowd")) if min_h is None else a["bbox"][3] < min_h

    small = [a for a in anns if not a.get("ignore") and is_small(a)]
    per_class = Counter(CONE_CLASSES[a["category_id"] - 1] for a in anns if not a.get("ignore") and not is_small(a))
    heights = np.array([a["bbox"][3] for a in anns if not a.get("ignore")]) if anns else np.zeros(0)  # labelled cones
    origin = info.get("origin", "render" if any("track" in im for im in ds.images) else "?")
    print(f"{args.dir}: {len(ds)} images ({', '.join(f'{s} ({n})' for s, n in sizes.items())}), {origin}, "
          f"{len(anns)} boxes")
    print("scored cones per class: " + ", ".join(f"{c} {per_class.get(c, 0)}" for c in CONE_CLASSES)
          + (f" (of which {masked} inside the ignore mask)" if masked else ""))
    print(f"too small (ignored): {len(small)} cones, {rule}")
    if regions:
        by = Counter(a.get("source_class", a["ignore"]) for a in regions)
        print("ignore regions (not misses): " + ", ".join(f"{c} {n}" for c, n in sorted(by.items())))
    for what, n in (info.get("rows_left_out") or {}).items():
        print(f"{what}: {n}")
    if info.get("projected_3d"):
        print(info["projected_3d"])
    if ds.has_ignore_mask:
        m = ds.ignore_mask(0)
        print(f"ignore mask: {info.get('ignore_mask') or 'per frame'} "
              f"({100.0 * float(m.mean()) if m is not None else 0.0:.1f} % of frame 0)")
    near, scored = edge_share(ds, scored=lambda a: not a.get("ignore") and not is_small(a))  # as counted above
    if scored:
        print(f"blue/yellow cones near the frame's edge (box centre beyond {EDGE_RADIUS:g} of the half-diagonal): "
              f"{near} of {scored} ({100.0 * near / scored:.1f} %; low light's damage grows with it, "
              "docs/calibration.md)")
    tracks = Counter(im.get("track") for im in ds.images if im.get("track"))
    if tracks:
        print("tracks: " + ", ".join(f"{t} ({n})" for t, n in sorted(tracks.items())))
    conds = Counter(f"{im['condition']}@{im.get('severity', 0)}" for im in ds.images if im.get("condition"))
    if conds:
        print("conditions: " + ", ".join(f"{c} ({n})" for c, n in sorted(conds.items())))
    k = ds.images[0].get("intrinsics") if ds.images else None
    if k:
        print("intrinsics (frame 0): " + ", ".join(f"{n} {v:.1f}" for n, v in k.items()))
    if heights.size:
        q = np.percentile(heights, [10, 50, 90])
        print(f"box height px: p10 {q[0]:.1f}, median {q[1]:.1f}, p90 {q[2]:.1f}")
    return 0


def _import(args) -> int:
    declare_inputs(args.src, args.mask, args.annotations)  # the source is read: the dataset goes elsewhere
    det = detector_from_args(args, required=False)
    ros_flags = [f for f, v in (("--topic", args.topic), ("--camera-info", args.camera_info), ("--start", args.start),
                                ("--end", args.end), ("--every", args.every != 1 or None)) if v is not None]
    if args.format == "rosbag":
        return _import_rosbag(args, det)
    if ros_flags:
        raise InputError(f"{', '.join(ros_flags)} go with the rosbag format, not {args.format}")
    r = import_dataset(args.format, args.src, args.out, classes=args.classes, condition=args.condition,
                       severity=args.severity, intrinsics=args.intrinsics, detector=det, mask=args.mask,
                       annotations=args.annotations, location_frame=args.location_frame, overwrite=args.overwrite,
                       resume=args.resume, project_3d=not args.no_project_3d,
                       progress=not args.quiet)
    cones = ", ".join(f"{c} {n}" for c, n in sorted(r["cones"].items())) or "none"
    size = "x".join(map(str, r["size"])) if r["size"] else "sizes " + ", ".join(f"{s} ({n})" for s, n in r["sizes"].items())
    print(f"imported {r['frames']} frames ({size}) into {r['out']}; layout: {r['layout']}")
    if r["resumed"] is not None:
        print(f"resumed: {r['resumed']} frames were already copied")
    print(f"cones: {cones}; too small: {r['too_small']} ({r['rule']})")
    if r["ignore_regions"]:
        print("ignore regions: " + ", ".join(f"{c} {n}" for c, n in sorted(r["ignore_regions"].items())))
    for what, n in r["rows_left_out"].items():
        print(f"{what}: {n}")
    if r.get("projected_3d"):
        print(r["projected_3d"])
    print(f"intrinsics: {r['intrinsics']}" + (f"; 3D locations: {r['location_frame']}" if args.format == "kitti" else ""))
    if r["condition"] is not None:
        print(f"condition: {r['condition']} (severity {r['severity']})")
    if r["converted"]:
        print(r["converted"], file=sys.stderr)
    orphans = r["labels_without_image"]
    if orphans:
        more = f" and {len(orphans) - 5} more" if len(orphans) > 5 else ""
        print(f"warning: {len(orphans)} label file(s) without an image were left out (listed in annotations.json "
              f"info.labels_without_image): {', '.join(orphans[:5])}{more}", file=sys.stderr)
    return 0


def _import_rosbag(args, det) -> int:
    other = [f for f, v in (("--classes", args.classes), ("--mask", args.mask), ("--annotations", args.annotations),
                            ("--no-project-3d", args.no_project_3d or None),
                            ("--location-frame", None if args.location_frame == "auto" else 1)) if v is not None]
    if other:
        raise InputError(f"{', '.join(other)} do not apply to a ROS bag (its frames are imported without labels)")
    r = import_rosbag(args.src, args.out, topic=args.topic, window=Window(args.start, args.end, args.every),
                      camera_info=args.camera_info, condition=args.condition, severity=args.severity,
                      intrinsics=args.intrinsics, detector=det, overwrite=args.overwrite, resume=args.resume,
                      progress=not args.quiet)
    size = "x".join(map(str, r["size"])) if r["size"] else "sizes " + ", ".join(f"{s} ({n})" for s, n in r["sizes"].items())
    span = (r["last_stamp_ns"] - r["first_stamp_ns"]) / 1e9
    print(f"imported {r['frames']} frames ({size}) of {r['topic']} ({r['msgtype']}; "
          f"{', '.join(f'{e} {n}' for e, n in r['encodings'].items())}) from a {r['kind']} bag ({r['storage']}) "
          f"into {r['out']}")
    if r["resumed"] is not None:
        print(f"resumed: {r['resumed']} frames were already written")
    print(f"header stamps {r['first_stamp_ns']} .. {r['last_stamp_ns']} ns ({span:.3f} s), kept per frame in "
          "annotations.json (stamp_ns, bag_time_ns)")
    print(f"intrinsics: {r['intrinsics']}" + (f" ({r['camera_info']})" if r["intrinsics"] == "camera_info" else ""))
    print("labels: none (cone topics are not projected into boxes; docs/ros.md)"
          + (f"; cone topics in the bag: {', '.join(r['cone_topics'])}" if r["cone_topics"] else ""))
    if r["condition"] is not None:
        print(f"condition: {r['condition']} (severity {r['severity']})")
    return 0


def _mask(args) -> int:
    if args.set is not None:
        declare_inputs(args.set)
        if args.preview is not None:
            raise InputError("--preview goes with --out (a proposal), not with --set")
        dest = set_dataset_mask(args.dir, args.set, frame=args.frame, overwrite=args.overwrite)
        print(f"stored {args.set} as {dest}")
        return 0
    if args.frame is not None:
        raise InputError("--frame goes with --set")
    declare_inputs(args.dir)  # a proposal reads the dataset: the mask and preview go elsewhere
    for p, what in ((args.out, "--out"), (args.preview, "--preview")):
        if p is not None:
            check_output(p, overwrite=args.overwrite, suffixes=(".png",), what=what)
    if args.max_frames < 4:
        raise InputError(f"--max-frames must be >= 4, got {args.max_frames}")
    ds = load_coco(args.dir)
    idx = np.unique(np.linspace(0, len(ds) - 1, min(args.max_frames, len(ds))).round().astype(int))
    frames = [ds.image(int(i)) for i in idx]
    mask = propose_mask(frames)
    write_mask(args.out, mask, overwrite=args.overwrite)
    print(f"proposed ignore mask from {len(frames)} frames: {100.0 * mask.mean():.1f} % of the frame -> {args.out}")
    if args.preview is not None:
        write_image(args.preview, mask_preview(frames[0], mask), overwrite=args.overwrite)
        print(f"preview: {args.preview}")
    print(f"check and edit it (white = ignored), then: weather-gym dataset mask {args.dir} --set {args.out}")
    return 0
