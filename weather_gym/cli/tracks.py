"""``weather-gym tracks list|show|export``: the shipped and generated cone tracks.

Examples:
    weather-gym tracks list
    weather-gym tracks show peanut --out peanut.png
    weather-gym tracks show random:7 --out random7.png
    weather-gym tracks show --all --out docs/img/tracks.png --overwrite
    weather-gym tracks export random:7 --out my_track.csv

The last command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['tracks', 'export', 'random:7', '--out', 'my_track.csv'])
    >>> args.tracks_command, args.track, str(args.out)
    ('export', 'random:7', 'my_track.csv')
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt

from weather_gym.core._figures import save_figure
from weather_gym.core._io import check_output
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.tracks import TRACKS, load_track, source_label
from weather_gym.tracks.plot import plot_track

ALL_SEED = 7
"""Seed of the random track drawn by ``show --all``."""


def register(sub) -> None:
    p = sub.add_parser("tracks", help="list, plot or export cone tracks",
                       description="The cone tracks: EUFS layouts shipped in tracks/, 'oval', 'random:SEED', "
                                   "or any cone CSV file.")
    cmds = p.add_subparsers(dest="tracks_command", metavar="ACTION", required=True)

    ls = cmds.add_parser("list", help="name, cones, length and event of every registered track")
    ls.add_argument("--seed", type=int, default=ALL_SEED, help="seed of the random track row (default %(default)s)")
    ls.set_defaults(func=_list)

    show = cmds.add_parser("show", help="plot a track (cones, centerline, start pose) to a PNG")
    show.add_argument("track", nargs="?", help="a track name, 'random:SEED' or a cone CSV path")
    show.add_argument("--all", action="store_true", help="plot every registered track in a grid")
    show.add_argument("--out", required=True, type=Path, help="PNG file to write")
    add_overwrite_arg(show, help="overwrite --out if it exists")
    show.add_argument("--seed", type=int, default=ALL_SEED, help="seed for 'random' (default %(default)s)")
    show.set_defaults(func=_show)

    exp = cmds.add_parser("export", help="write a track's cones as a CSV in the EUFS format")
    exp.add_argument("track", help="a track name, 'random:SEED' or a cone CSV path")
    exp.add_argument("--out", required=True, type=Path, help="CSV file to write (never overwritten without --overwrite)")
    add_overwrite_arg(exp, help="overwrite --out if it exists")
    exp.add_argument("--seed", type=int, default=None, help="seed for 'random'")
    exp.set_defaults(func=_export)


def _list(args) -> int:
    print(f"{'name':<16}{'cones':>7}{'length m':>10}  {'event':<13}source")
    for name in TRACKS.names():
        t = load_track(name, seed=args.seed)
        shown = f"random:{args.seed}" if name == "random" else name
        print(f"{shown:<16}{len(t.cones_xy):>7}{t.length:>10.1f}  {t.event:<13}{source_label(t.source)}")
    return 0


def _show(args) -> int:
    matplotlib.use("Agg")


    if args.all == (args.track is not None):
        raise InputError("give either a TRACK or --all")
    check_output(args.out, overwrite=args.overwrite, suffixes=(".png",), what="--out")
    if args.all:
        names = TRACKS.names()
        cols = 4
        rows = -(-len(names) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.9 * rows))
        for ax, name in zip(axes.flat, names, strict=False):
            t = load_track(name, seed=args.seed)
            shown = f"random:{args.seed}" if name == "random" else name
            plot_track(t, ax, title=f"{shown}: {t.length:.0f} m, {len(t.cones_xy)} cones ({t.event})")
        for ax in list(axes.flat)[len(names):]:
            ax.axis("off")
        fig.legend(*_legend(axes), loc="lower right", fontsize=10, ncol=2)
    else:
        fig, ax = plt.subplots(figsize=(8, 8))
        plot_track(load_track(args.track, seed=args.seed), ax)
        ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    save_figure(fig, args.out, overwrite=args.overwrite, dpi=110)
    print(f"wrote {args.out}")
    return 0


def _legend(axes):
    seen: dict[str, object] = {}
    for ax in axes.flat:
        for h, label in zip(*ax.get_legend_handles_labels(), strict=True):
            seen.setdefault(label, h)
    return list(seen.values()), list(seen.keys())


def _export(args) -> int:
    check_output(args.out, overwrite=args.overwrite, suffixes=(".csv",), what="--out")
    track = load_track(args.track, seed=args.seed)
    track.to_csv(args.out, overwrite=args.overwrite)
    print(f"wrote {args.out} ({len(track.cones_xy)} cones, {track.length:.1f} m centerline)")
    return 0
