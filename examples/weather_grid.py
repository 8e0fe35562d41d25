"""Render one simulator frame under every weather effect at k = 0.25, 0.5, 0.75 (a grid PNG).

Run (writes docs/img/weather_grid.png):

    python examples/weather_grid.py --overwrite

Rows are the effects of the registry (plus dim's physical and night modes, refractive and persistent
droplets; ``--only droplets,dim`` keeps the rows of those effects), columns the
clean frame and k = 0.25 / 0.5 / 0.75. The frame comes from ``WeatherGym/ConeTrack-v0`` after a
few steps of driving (its depth map and state go to the effects); ``--image PATH`` uses an image
file instead, ``--synthetic`` the synthetic scene of ``weather_gym.weather.sample``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.weather import EFFECTS, make

KS = (0.25, 0.5, 0.75)
ROWS = [(name, {}) for name in EFFECTS.names()] + [("dim", {"mode": "physical"}), ("dim", {"mode": "night"}),
                                                   ("droplets", {"mode": "refractive"}),
                                                   ("droplets", {"persistent": True})]
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "weather_grid.png"


def simulator_frame(seed: int = 0, steps: int = 20):
    """``(image, depth, state)`` from the simulator after ``steps`` steps at gentle throttle."""
    import gymnasium as gym

    import weather_gym  # noqa: F401  (registers the env ids)

    env = gym.make("WeatherGym/ConeTrack-v0")
    try:
        obs, info = env.reset(seed=seed)
        for _ in range(steps):
            obs, *_, info = env.step(np.array([0.0, 0.4], np.float32))
        cam = info.get("camera")
        state = {"speed": float(obs["state"][0]), "yaw_rate": float(obs["state"][1])}
        if cam is not None:
            state["fx"] = 0.5 * cam.width / np.tan(np.radians(cam.hfov_deg) / 2)
            state["exposure_s"] = cam.exposure_s
        return obs["image"], obs["depth"], state
    finally:
        env.close()


def grid(image: np.ndarray, depth: np.ndarray | None, state: dict, tile_w: int = 288, seed: int = 0,
         only: tuple[str, ...] = ()) -> np.ndarray:
    """The grid as one uint8 RGB image with row and column labels (``only``: these effects' rows)."""
    h, w = image.shape[:2]
    tile_h = int(round(tile_w * h / w))
    label_w, head_h = 190, 28
    font = cv2.FONT_HERSHEY_SIMPLEX

    def tile(img):
        return cv2.resize(img, (tile_w, tile_h), interpolation=cv2.INTER_AREA)

    rows = []
    head = np.full((head_h, label_w + tile_w * (1 + len(KS)), 3), 255, np.uint8)
    for i, text in enumerate(["clean", *[f"k = {k}" for k in KS]]):
        cv2.putText(head, text, (label_w + i * tile_w + 8, 20), font, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    rows.append(head)
    for name, params in ROWS:
        if only and name not in only:
            continue
        label = np.full((tile_h, label_w, 3), 255, np.uint8)
        cv2.putText(label, name, (8, tile_h // 2), font, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
        if params:
            extra = ", ".join(f"{k}={v}" for k, v in params.items())
            cv2.putText(label, extra, (8, tile_h // 2 + 22), font, 0.45, (60, 60, 60), 1, cv2.LINE_AA)
        cells = [label, tile(image)]
        for k in KS:
            effect = make(name, k=k, **params)
            effect.reset(seed)
            cells.append(tile(effect(image, depth=depth, state=state)))
        rows.append(np.hstack(cells))
    return np.vstack(rows)


def main(argv: list[str] | None = None) -> int:
    from weather_gym.cli import run_command

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    src = p.add_mutually_exclusive_group()
    src.add_argument("--image", type=Path, help="use this image instead of a simulator frame")
    src.add_argument("--synthetic", action="store_true", help="use the synthetic scene (no simulator)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="PNG to write (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", default="", metavar="NAME,...",
                   help="only the rows of these effects, e.g. droplets,dim (every mode of each)")
    add_overwrite_arg(p, help="overwrite --out if it exists")
    return run_command(_run, p.parse_args(argv))


def _run(args) -> int:
    from weather_gym.core._io import check_output, write_image
    from weather_gym.lab.datasets.coco import read_image

    check_output(args.out, overwrite=args.overwrite, suffixes=(".png",), what="--out")
    if args.synthetic:
        from weather_gym.weather.sample import sample_frame

        image, depth = sample_frame(376, 672, seed=args.seed)
        state = {"speed": 10.0, "yaw_rate": 0.2}
    elif args.image is not None:
        image, depth, state = read_image(args.image), None, {}
    else:
        image, depth, state = simulator_frame(args.seed)
    only = tuple(n for n in args.only.split(",") if n)
    unknown = [n for n in only if n not in EFFECTS.names()]
    if unknown:
        from weather_gym.core.errors import InputError

        raise InputError(f"--only: unknown effect(s) {', '.join(unknown)}; known: {', '.join(EFFECTS.names())}")
    out = grid(image, depth, state, seed=args.seed, only=only)
    write_image(args.out, out, overwrite=args.overwrite, params=[cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {args.out} ({out.shape[1]}x{out.shape[0]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
