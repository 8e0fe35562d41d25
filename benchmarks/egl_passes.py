"""Where the EGL frame's time goes: the default camera env step with parts of PyBullet's EGL plugin
switched off, next to the naive TinyRenderer frame of ``weather-gym bench sim --naive``.

    python benchmarks/egl_passes.py [--repeats 30] [--track small_track]

At 672x376 and 336x188, the rows taking turns call by call:

- the naive TinyRenderer frame (the baseline);
- the default camera env step (``make_env()``: physics, EGL frame with its segmentation pass and its
  shadow map redrawn only where something moved, camera model, ground truth);
- the same with the plugin's window clears confined to the image (a GL scissor around each clear of
  its 2560x2048 window; the frames keep their bytes, checked);
- the same with ``SimConfig(shadows=False)``: without the plugin's 4096x4096 shadow-map pass (other
  frames: how much they change is printed).

The clears row is a diagnostic, not something the env does: the plugin offers no switch for it, so
this script points the ``glClear`` entry of the plugin's GL pointer table
(``weather_gym.sim.egl.gl_table.GLTableEntry``) at a scissoring one. Linux, 64-bit, with the EGL
plugin loading; otherwise it says why and exits.
"""

from __future__ import annotations

import argparse
import os
import sys
from functools import partial

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.lab.bench._timing import interleaved_ms, machine_line, markdown_table
from weather_gym.lab.bench.sim import NAIVE_SIZES, _Driver, _driving_actions
from weather_gym.pipeline import make_env
from weather_gym.sim import renderer as _renderer
from weather_gym.sim.baseline import naive_scene
from weather_gym.sim.config import SimConfig
from weather_gym.sim.egl.elf_symbols import SymbolUnavailable
from weather_gym.sim.egl.gl_table import (
    FOUR_INTS,
    GL_SCISSOR_TEST,
    ONE_ENUM,
    GLTableEntry,
    draw_framebuffer,
    gl_function,
)


class ScissoredClears:
    """Points the loaded EGL plugin's ``glClear`` at one that, while ``size`` is set, confines clears
    of the window (not of the shadow map's framebuffer) to the ``(w, h)`` image in its corner."""

    def __init__(self) -> None:
        self._clear = gl_function("glClear", ONE_ENUM)
        self._enable, self._disable = gl_function("glEnable", ONE_ENUM), gl_function("glDisable", ONE_ENUM)
        self._scissor = gl_function("glScissor", FOUR_INTS)
        self.size: tuple[int, int] | None = None
        try:
            self._entry = GLTableEntry("glClear", ONE_ENUM(self._scissored_clear))
        except (SymbolUnavailable, LookupError) as exc:
            raise SystemExit(str(exc)) from None

    def _scissored_clear(self, mask: int) -> None:
        if self.size is not None and draw_framebuffer() == 0:  # the window, not the shadow map's framebuffer
            self._enable(GL_SCISSOR_TEST)
            self._scissor(0, 0, *self.size)
            self._clear(mask)
            self._disable(GL_SCISSOR_TEST)
            return
        self._clear(mask)

    def around(self, fn, size: tuple[int, int]):
        """``fn`` with the clears confined while it runs."""
        def run():
            self._entry.ensure()  # the plugin reloads its table for every new EGL context
            self.size = size
            try:
                return fn()
            finally:
                self.size = None
        return run


def _frames(env, actions, steps: int, wrap=lambda fn: fn) -> list[np.ndarray]:
    """The images of ``steps`` steps of a seed-0 episode, each step run through ``wrap``."""
    env.reset(seed=0)
    return [wrap(lambda a=a: env.step(a)[0]["image"])() for a in actions[:steps]]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--track", default="small_track", help="track to drive (default: small_track)")
    parser.add_argument("--repeats", type=int, default=30, help="timed calls per row (median is reported)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")
    actions = _driving_actions(args.track, 400)
    clears: ScissoredClears | None = None
    rows, changes = [], []
    for w, h in NAIVE_SIZES:
        cam = CameraConfig(width=w, height=h)
        frame, close = naive_scene(cam)
        envs = [make_env(track=args.track, camera=cam) for _ in range(2)]
        envs.append(make_env(track=args.track, camera=cam, sim=SimConfig(shadows=False)))
        try:
            drivers = [_Driver(env, actions) for env in envs]
            if drivers[0].info["renderer"] != "egl":
                raise SystemExit("the default env does not render with EGL here: nothing to take apart")
            clears = clears or ScissoredClears()
            ms = interleaved_ms({"naive": frame, "default": drivers[0],
                                 "clears": clears.around(drivers[1], (w, h)), "no_shadow_map": drivers[2]},
                                repeats=args.repeats, warmup=3, budget_s=1e9, run=0)
            stock = _frames(envs[0], actions, 60)
            confined = _frames(envs[1], actions, 60, partial(clears.around, size=(w, h)))
            bare = _frames(envs[2], actions, 60)
        finally:
            close()
            for env in envs:
                env.close()
        diff = [np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1) for a, b in zip(stock, bare, strict=True)]
        same = all(np.array_equal(a, b) for a, b in zip(stock, confined, strict=True))
        changes.append([f"{w}x{h}", "yes" if same else "NO", f"{np.mean([np.mean(d > 0) for d in diff]):.1%}",
                        f"{np.mean([np.mean(d > 10) for d in diff]):.2%}", f"{np.mean([d.mean() for d in diff]):.3f}"])
        for key, label in (("naive", "naive TinyRenderer frame (baseline)"),
                           ("default", "default camera env step, EGL"),
                           ("clears", "the same, window clears confined to the image"),
                           ("no_shadow_map", "the same with shadows=False (no shadow-map pass)")):
            rows.append([f"{w}x{h}", label, ms[key], ms["naive"] / ms[key]])
    print(f"Machine: {machine_line()}; EGL: {_renderer.renderer_detail()}; load average "
          f"{os.getloadavg()[0]:.2f} at the end")
    print(f"Track: {args.track}, driven by gt_pure_pursuit from a seed-0 start; median of {args.repeats} calls "
          "per row, the rows taking turns call by call")
    print(markdown_table(["resolution", "row", "ms per call", "speed-up vs naive frame"], rows))
    print()
    print("Frames of the first 60 steps of the same episode, against the default step's:")
    print(markdown_table(["resolution", "clears confined: same bytes", "shadows=False: pixels changed",
                          "changed by > 10", "mean abs change (max over channels)"], changes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
