"""Make the gap workflow's demo inputs: "measured" frames whose weather the workflow is not told.

The study's low-light case: its dimming missed what a real camera does in fading light (blur, the
camera raising its gain). This script renders 200 clean frames of ``small_track`` at 672x376 with
random looks, applies dimming plus sensor noise plus defocus blur to a copy (the "measured" set;
nothing about that weather is written into it), and writes a model file with dimming alone at a
wrong k, which is what the study's simulator had:

    python examples/gap_demo.py --out scratch/gap_demo
    weather-gym gap scratch/gap_demo/measured --model scratch/gap_demo/model.toml \\
        --cache scratch/gap_demo/cache --out docs/gap/demo

The second command is the workflow: it re-renders the measured views, finds that the model's k is
wrong and that noise and blur are missing, and writes the updated model, ``report.json``,
``report.md`` and the plots (``docs/gap.md`` walks through them). Both steps resume and never
overwrite: delete ``--out`` to start over.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

HIDDEN = [{"name": "blur", "k": 0.5}, {"name": "dim", "k": 0.55}, {"name": "noise", "k": 0.3}]
MODEL = '# dimming alone, with the wrong k: what the study\'s simulator had\n[[effects]]\nname = "dim"\nk = 0.3\n'


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("scratch/gap_demo"), help="folder for clean/, measured/, model.toml")
    ap.add_argument("--frames", type=int, default=200, help="frames to render (default 200)")
    ap.add_argument("--seed", type=int, default=11, help="render seed (default 11)")
    ap.add_argument("--measured-seed", type=int, default=4242,
                    help="seed of the hidden weather's random numbers (default 4242, not the workflow's)")
    args = ap.parse_args(argv)

    from weather_gym.camera.isp import CameraModel
    from weather_gym.core._io import atomic_write
    from weather_gym.lab.datasets import render_dataset
    from weather_gym.lab.gap import degrade_dataset

    clean, measured, model = args.out / "clean", args.out / "measured", args.out / "model.toml"
    t0 = time.perf_counter()
    if not (clean / "annotations.json").exists():
        # the study's ideal camera: the hidden weather is then the only thing in the frames besides the scene
        render_dataset(clean, tracks=["small_track"], frames=args.frames, seed=args.seed, randomize=True,
                       frames_per_episode=10, resume=True, camera_model=CameraModel.ideal())
    t1 = time.perf_counter()
    if not (measured / "annotations.json").exists():
        degrade_dataset(clean, measured, HIDDEN, seed=args.measured_seed, progress=True)
    if not model.exists():
        atomic_write(model, MODEL)
    t2 = time.perf_counter()
    print(f"clean set {clean} ({t1 - t0:.0f} s), measured set {measured} ({t2 - t1:.0f} s), model {model}")
    hidden = ", ".join(f"{e['name']} k={e['k']}" for e in HIDDEN)
    print(f"hidden weather: {hidden}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
