"""The plain world next to the realistic one and a few domain-randomised frames (a grid PNG).

Run (writes docs/img/world.png):

    python examples/world_grid.py --overwrite

Top row: the plain (default) world and the realistic world (``SimConfig(scene="realistic")``, default
``REALISTIC_LOOK`` with the ego car in view, ``CameraModel.realistic()``) from the same pose; the
realistic world through a camera like the real Estoril one (59 deg, tilted 10 deg, 1.15 m); frames
drawn by ``weather_gym.sim.randomize.sample_realistic`` (what ``weather-gym dataset render --randomize`` renders),
with their ground-truth boxes in green.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from weather_gym.core._output_args import add_overwrite_arg

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "world.png"


def _frame(env, seed: int, options: dict, boxes: bool) -> np.ndarray:
    obs, info = env.reset(seed=seed, options=options)
    img = np.ascontiguousarray(obs["image"])
    if boxes:
        for x0, y0, x1, y1 in np.asarray(info["gt"]["boxes"]).astype(int):
            cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), (40, 230, 40), 1)
    return img


def _label(img: np.ndarray, text: str) -> np.ndarray:
    img = img.copy()
    cv2.rectangle(img, (0, 0), (8 + 9 * len(text), 22), (0, 0, 0), -1)
    cv2.putText(img, text, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="PNG to write (default %(default)s)")
    p.add_argument("--track", default="small_track")
    p.add_argument("--seed", type=int, default=0, help="seed of the randomised frames")
    add_overwrite_arg(p, help="overwrite --out if it exists")
    args = p.parse_args(argv)

    from weather_gym.camera.config import CameraConfig
    from weather_gym.camera.isp import CameraModel
    from weather_gym.core._io import check_output, write_image
    from weather_gym.envs import ConeTrackEnv, EnvConfig
    from weather_gym.sim.config import SimConfig
    from weather_gym.sim.look import DEFAULT_LOOK, REALISTIC_LOOK
    from weather_gym.sim.randomize import sample_realistic

    check_output(args.out, overwrite=args.overwrite, suffixes=(".png",), what="--out")
    plain = ConeTrackEnv(EnvConfig(track=args.track))
    real = ConeTrackEnv(EnvConfig(track=args.track, sim=SimConfig(scene="realistic")))
    # a camera like the real Estoril one (fx 900 px at 1024 wide: 59 deg), higher and tilted down more
    like_real = ConeTrackEnv(EnvConfig(track=args.track, sim=SimConfig(scene="realistic"),
                                       camera=CameraConfig(hfov_deg=59.0, pitch_deg=10.0, mount_height=1.15)))
    try:
        start = {"start_s": 6.0}
        tiles = [_label(_frame(plain, 0, {**start, "look": DEFAULT_LOOK}, False), "plain (default)"),
                 _label(_frame(real, 0, {**start, "look": REALISTIC_LOOK,
                                         "camera_model": CameraModel.realistic()}, False),
                        "realistic + camera model"),
                 _label(_frame(like_real, 0, {**start, "look": REALISTIC_LOOK, "camera_model": CameraModel.realistic()},
                               False), "realistic, 59 deg camera tilted 10 deg")]
        track = real.track
        rng = np.random.default_rng(args.seed)
        for i in range(3):
            draw = sample_realistic(rng)
            s = float(rng.uniform(0, track.length))
            tiles.append(_label(_frame(real, i, {"start_s": s, "look": draw.look, "camera_model": draw.camera_model},
                                       True), f"randomized {i + 1} (GT boxes)"))
    finally:
        plain.close()
        real.close()
        like_real.close()
    rows = [np.hstack(tiles[i:i + 2]) for i in range(0, len(tiles), 2)]
    grid = np.vstack(rows)
    grid = cv2.resize(grid, (grid.shape[1] * 3 // 4, grid.shape[0] * 3 // 4), interpolation=cv2.INTER_AREA)
    write_image(args.out, grid, overwrite=args.overwrite, params=[cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
