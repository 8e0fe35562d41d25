"""Where in the frame a set's cones are, against how much of its mAP a preset takes.

At the steep low-light presets the held-out tracks spread by more than a preset may miss by. This
script puts each set's relative mAP (from ``transfer.py`` outputs) next to two properties of the set:
the share of its blue and yellow cones that the camera sees near the frame's edge
(:mod:`weather_gym.lab.datasets.frame_position`: box centre beyond 0.8 of the frame's half-diagonal
ellipse, the corners and the far left and right; `weather-gym dataset info` prints it too), and the
mean absolute yaw rate of the car over the set's frames (the turns' motion blur). It writes
``OUT/placement.csv`` (one row per set), ``OUT/placement.md`` (per preset: the correlation of relative
mAP with each property over the sets, and the least-squares slope) and ``OUT/placement.png``.

Each ``--transfer DIR`` (a ``transfer.py`` output folder) is followed by the ``--set NAME=DIR`` it was
run with; only rendered sets (records with a ``track``) are used, so real frames are left out.

    python docs/calibration/placement.py --transfer docs/calibration/transfer/held240 \
        --set b_shape=scratch/calib/held240_b_shape --set oval=scratch/calib/held240_oval ... --out /tmp/placement
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.frame_position import EDGE_RADIUS, edge_share

PRESETS = (("low_light", 1), ("low_light", 2), ("low_light", 3), ("droplets", 4))
TOLERANCE = 0.05


def set_properties(folder: Path) -> dict[str, float] | None:
    """Frames, blue/yellow cones, the share of them near the frame's edge and the mean |yaw rate|;
    None when the set's records are not rendered ones (no ``track``)."""
    ds = load_coco(folder)
    if not len(ds) or not all("track" in im for im in ds.images):
        return None
    near, total = edge_share(ds)
    yaw = np.abs([float(im.get("yaw_rate", 0.0)) for im in ds.images])
    return {"frames": len(ds), "cones": total, "edge_share": near / max(total, 1),
            "mean_abs_yaw_rate": float(yaw.mean())}


def read_group(folder: Path, paths: dict[str, Path]) -> list[dict]:
    """One row per rendered set of a ``transfer.py`` output folder: its properties and relative mAPs."""
    table = {(r["condition"], int(r["severity"])): r for r in csv.DictReader(open(folder / "transfer.csv"))}
    rows = []
    for name, path in paths.items():
        props = set_properties(path)
        if props is None:
            continue
        row = {"group": folder.name, "set": name, **props}
        for cond, sev in PRESETS:
            if name not in table[(cond, sev)]:
                raise SystemExit(f"{folder / 'transfer.csv'}: no column {name!r} (its sets: "
                                 f"{', '.join(k for k in table[(cond, sev)] if not k.endswith('_sd'))})")
            row[f"{cond}@{sev}"] = float(table[(cond, sev)][name])
        rows.append(row)
    return rows


def _per_group(rows: list[dict], groups: list[str], key: str) -> str:
    """``group r`` of the edge share against ``key`` within each folder (sets of 3 or more)."""
    out = []
    for g in groups:
        sel = [r for r in rows if r["group"] == g]
        if len(sel) >= 3:
            out.append(f"{g} {np.corrcoef([r['edge_share'] for r in sel], [r[key] for r in sel])[0, 1]:.2f} ({len(sel)})")
    return ", ".join(out)


class _Group(argparse.Action):
    """``--transfer DIR`` opens a group; each ``--set NAME=DIR`` after it belongs to it."""

    def __call__(self, parser, namespace, value, option_string=None):
        groups = getattr(namespace, "groups", None) or {}
        if option_string == "--transfer":
            groups[Path(value)] = {}
        else:
            if not groups:
                parser.error("--set must follow the --transfer folder it was checked in")
            name, sep, path = value.partition("=")
            if not sep or not name or not path:
                parser.error(f"--set must be NAME=DIR, got {value!r}")
            groups[list(groups)[-1]][name] = Path(path)
        namespace.groups = groups


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--transfer", action=_Group, required=True, metavar="DIR", help="a transfer.py output folder")
    ap.add_argument("--set", action=_Group, metavar="NAME=DIR", help="a set of the --transfer folder before it")
    ap.add_argument("--reference", action="append", default=[], metavar="NAME=DIR",
                    help="a set to mark by its edge share only (e.g. the calibration pool)")
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args(argv)
    refs = {}
    for text in args.reference:
        name, sep, path = text.partition("=")
        props = set_properties(Path(path)) if sep and name else None
        if props is None:
            raise SystemExit(f"--reference must be NAME=DIR of a rendered set, got {text!r}")
        refs[name] = props
    args.dirs = list(args.groups)
    rows = [r for d, paths in args.groups.items() for r in read_group(d, paths)]
    if len(rows) < 3:
        raise SystemExit(f"need at least 3 rendered sets, got {len(rows)} in {', '.join(map(str, args.dirs))}")
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "placement.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)

    targets = {(r["condition"], int(r["severity"])): float(r["target"])
               for r in csv.DictReader(open(args.dirs[0] / "transfer.csv"))}
    edge = np.array([r["edge_share"] for r in rows])
    yaw = np.array([r["mean_abs_yaw_rate"] for r in rows])
    lines = [f"{len(rows)} rendered sets ({', '.join(d.name for d in args.dirs)}); edge share: blue and yellow cones "
             f"with their box centre beyond {EDGE_RADIUS} of the half-diagonal ellipse, {edge.min():.2f}-{edge.max():.2f}.",
             *[f"\n{name}: edge share {p['edge_share']:.2f}, mean abs yaw rate {p['mean_abs_yaw_rate']:.2f} rad/s "
               f"({p['frames']} frames)." for name, p in refs.items()],
             "",
             f"Edge share against mean abs yaw rate over the sets: r = {np.corrcoef(edge, yaw)[0, 1]:.2f}.",
             "",
             "| preset | target | r with edge share | slope per 0.1 edge share | sd of the residual "
             f"| edge share where the fit is within {TOLERANCE} | r with mean abs yaw rate | r with edge share, per folder |",
             "|---|---|---|---|---|---|---|---|"]
    groups = list(dict.fromkeys(r["group"] for r in rows))
    for cond, sev in PRESETS:
        v = np.array([r[f"{cond}@{sev}"] for r in rows])
        slope, icpt = np.polyfit(edge, v, 1)
        resid = v - (slope * edge + icpt)
        t = targets[(cond, sev)]
        ends = sorted((t + d - icpt) / slope for d in (-TOLERANCE, TOLERANCE)) if abs(slope) > 0.05 else None
        window = f"{max(ends[0], 0):.2f}-{min(ends[1], 1):.2f}" if ends else "any"
        lines.append(f"| {cond}@{sev} | {t:.3f} | {np.corrcoef(edge, v)[0, 1]:.2f} | "
                     f"{0.1 * slope:+.3f} | {resid.std(ddof=2):.3f} (of {v.std(ddof=1):.3f}) | {window} | "
                     f"{np.corrcoef(yaw, v)[0, 1]:.2f} | {_per_group(rows, groups, f'{cond}@{sev}')} |")
    (args.out / "placement.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [p for p in PRESETS if p[0] == "low_light"][:2]
    fig, axes = plt.subplots(1, len(shown), figsize=(5 * len(shown), 3.8))
    for ax, (cond, sev) in zip(np.atleast_1d(axes), shown, strict=True):
        t = targets[(cond, sev)]
        ax.axhspan(t - TOLERANCE, t + TOLERANCE, color="0.9", label=f"target ± {TOLERANCE}")
        ax.axhline(t, color="k", lw=1)
        for g in groups:
            sel = [r for r in rows if r["group"] == g]
            ax.scatter([r["edge_share"] for r in sel], [r[f"{cond}@{sev}"] for r in sel], s=18, label=g)
        v = np.array([r[f"{cond}@{sev}"] for r in rows])
        slope, icpt = np.polyfit(edge, v, 1)
        xs = np.linspace(edge.min(), edge.max(), 2)
        ax.plot(xs, slope * xs + icpt, "k--", lw=1, label=f"fit (r = {np.corrcoef(edge, v)[0, 1]:.2f})")
        for name, p in refs.items():
            ax.axvline(p["edge_share"], color="0.4", ls=":", lw=1)
            ax.annotate(name, (p["edge_share"], ax.get_ylim()[1]), fontsize=7, ha="left", va="top", rotation=90)
        ax.set_xlabel(f"share of blue/yellow cones near the frame's edge (r > {EDGE_RADIUS})")
        ax.set_ylabel("relative mAP (blue, yellow)")
        ax.set_title(f"{cond.replace('_', ' ')} S{sev}")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out / "placement.png", dpi=110)


if __name__ == "__main__":
    main()
