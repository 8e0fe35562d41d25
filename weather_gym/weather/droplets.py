"""Adherent water droplets on the lens: the study's effect, byte-exact and ~20x faster.

**Meaning of k**: the opacity knob of the study (Albumentations ``alpha_coef``). Every droplet is a
white disc blended with ``alpha = fog_coef * k`` (0.4 k with the study's ``fog_coef``), so a pixel
under ``n`` droplets becomes ``255 (1 - (1 - alpha)^n) + I (1 - alpha)^n``. The layout (number, size
and place of the discs) depends only on the image size, ``fog_coef`` and the random generator: discs
of radius ``hw // 2`` with ``hw = max(int(W // 3 * fog_coef), 10)``, drawn uniformly in nested boxes
around the image centre, so coverage is densest where the far cones are. Below about 75 px of
image width the study's algorithm draws no disc at all.

**Speed**: the study drew every disc on two full-image copies and blended the whole frame per disc.
Here each disc is blended only inside its own bounding box, with the study's own ``addWeighted``
(:func:`render_discs`), so the output is identical to the study's recipe
(:func:`weather_gym.weather.reference.study_droplets`) byte for byte, for the same layout.

**Persistent mode** (``persistent=True``): real droplets stick to the lens. The first frame of an
episode is the study's layout; from then on droplets stay where they are, grow slowly
(``growth_per_s``), new small ones land (``spawn_per_s``, as a fraction of the study's count per
second, placed with the study's distribution), overlapping ones merge (area-conserving) and those
grown past ``run_radius`` times the study's radius run down the lens (``run_speed`` image heights per
second) and off it. :meth:`Droplets.wipe` clears the lens. The defaults keep the count roughly
around the study's.

**Refractive mode** (``mode="refractive"``, spec ``droplets:0.7:mode=refractive``): each drop is a
refracting spherical cap that shows an inverted, blurred image of the scene around it, with a dark
rim and a highlight (:mod:`weather_gym.weather.lens_drops`). ``k`` is then how wet the lens is:
of ``drop_count`` drops (radii around ``drop_radius`` image heights, contact angles around
``contact_deg``) those whose own draw is below ``k`` are shown, their radii scaled by
``(1 + k) / 2``. Persistence, merging, running and :meth:`Droplets.wipe` work as above. The faithful
mode ignores the refractive parameters, the refractive mode ignores ``fog_coef``.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.zeros((376, 672, 3), np.uint8)
    >>> out = make("droplets", k=0.55)(img, rng=np.random.default_rng(0))
    >>> out.shape, int(np.unique(out)[1])  # one droplet over black: 255 * 0.4 * 0.55 = 56.1
    ((376, 672, 3), 56)
    >>> rain = make("droplets", k=0.55, persistent=True)
    >>> rain.reset(3); a = rain(img); b = rain(img); rain.wipe()
    >>> lens = make("droplets", k=0.7, mode="refractive")
    >>> bool((lens(img, rng=np.random.default_rng(0)) != img).any())
    True
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, ClassVar

import cv2
import numpy as np

from weather_gym.weather.base import EffectRun, KnobEffect
from weather_gym.weather.lens_drops import drop_layout, render_lens_drops
from weather_gym.weather.reference import STUDY_FOG_COEF, fog_layout
from weather_gym.weather.registry import register_effect

__all__ = ["DiscDraw", "Droplets", "LensDraw", "render_discs"]


@lru_cache(maxsize=64)
def _white_disc(r: int) -> np.ndarray:
    """A filled white disc of radius ``r`` drawn by ``cv2.circle`` on black, RGB (read-only)."""
    mask = np.zeros((2 * r + 1, 2 * r + 1), np.uint8)
    cv2.circle(mask, (r, r), r, 255, -1)
    disc = cv2.cvtColor(mask, cv2.COLOR_GRAY2RGB)
    disc.setflags(write=False)
    return disc


def render_discs(img: np.ndarray, centres: np.ndarray | Sequence[Sequence[int]],
                 radii: np.ndarray | Sequence[int], alpha: float, out: np.ndarray | None = None) -> np.ndarray:
    """Blend white discs one after another, each only inside its bounding box (into ``out`` or new).

    ``centres``: ``(x, y)`` pairs, ``radii``: one int per disc (arrays or lists). Identical, pixel
    for pixel, to drawing each disc on a full-image copy and blending the whole frame with
    ``cv2.addWeighted(overlay, alpha, frame, 1 - alpha, 0)`` as the study did. Per disc, two
    OpenCV calls on its bounding box: the same ``addWeighted`` of the white disc (black around it)
    and the pixels, then the maximum of that and the pixels. Inside the disc the blend towards
    white is never below the pixel, so the maximum is the study's value; outside it the blend is
    ``(1 - alpha) I <= I``, so the pixel stays as it was.
    """
    if out is None:
        out = img.copy()
    else:
        np.copyto(out, img)
    h, w = img.shape[:2]
    beta = 1.0 - alpha
    if isinstance(centres, np.ndarray):
        centres = centres.tolist()
    if isinstance(radii, np.ndarray):
        radii = radii.tolist()
    last_r, disc = -1, np.zeros((0, 0), np.uint8)  # replaced at the first disc
    for (cx, cy), r in zip(centres, radii, strict=True):
        x0, y0 = max(cx - r, 0), max(cy - r, 0)
        x1, y1 = min(cx + r + 1, w), min(cy + r + 1, h)
        if x0 >= x1 or y0 >= y1:
            continue
        if r != last_r:
            disc, last_r = _white_disc(r), r
        roi = out[y0:y1, x0:x1]
        blend = cv2.addWeighted(disc[y0 - cy + r:y1 - cy + r, x0 - cx + r:x1 - cx + r], alpha, roi, beta, 0)
        cv2.max(roi, blend, dst=roi)
    return out


@dataclass
class _Drops:
    """Per-episode droplet state of the persistent mode (centres and radii in pixels)."""

    shape: tuple[int, int]
    base_radius: float
    base_count: int
    x: np.ndarray
    y: np.ndarray
    r: np.ndarray
    frames: int = 0
    theta: np.ndarray | None = None  # refractive mode: contact angles (deg)
    u: np.ndarray | None = None  # refractive mode: visibility draws (shown when u < k)

    def extras(self) -> list[str]:
        """Names of the per-drop arrays besides ``x, y, r`` (the refractive mode's)."""
        return [] if self.theta is None else ["theta", "u"]

    def take(self, keep: np.ndarray) -> None:
        """Keep the drops selected by ``keep`` (a boolean mask or index array)."""
        for name in ("x", "y", "r", *self.extras()):
            setattr(self, name, getattr(self, name)[keep])


@dataclass
class _Lens:
    """The per-episode state of a droplets run: the persistent drops (``None`` until the first frame)."""

    drops: _Drops | None = None


@dataclass(frozen=True)
class DiscDraw:
    """One frame of the faithful mode: disc centres ``(x, y)`` and radii, in pixels."""

    centres: np.ndarray | list = field(repr=False)
    radii: np.ndarray | list = field(repr=False)


@dataclass(frozen=True)
class LensDraw:
    """One frame of the refractive mode: every drop (shown when ``u < k``), pixels and degrees."""

    x: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    r: np.ndarray = field(repr=False)
    theta: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)


@register_effect
@dataclass(frozen=True)
class Droplets(KnobEffect):
    """Adherent droplets; ``k`` = droplet opacity (the study's ``alpha_coef``). See module doc."""

    name: ClassVar[str] = "droplets"
    CHAIN_RANK: ClassVar[float] = 40
    NOMINAL_K: ClassVar[tuple[float, ...] | None] = None  # its presets rows are calibrated
    stateful: ClassVar[bool] = True

    fog_coef: float = STUDY_FOG_COEF
    persistent: bool = False
    fps: float = 30.0
    spawn_per_s: float = 0.03
    growth_per_s: float = 0.02
    run_radius: float = 1.6
    run_speed: float = 0.5
    merge_frac: float = 0.35
    mode: str = "faithful"
    drop_count: int = 100
    drop_radius: float = 0.055
    contact_deg: float = 60.0
    hfov_deg: float = 90.0
    look_up: float = 0.3
    defocus: float = 0.006
    blur: float = 0.02
    rim: float = 0.6
    highlight: float = 0.5

    PARAM_BOUNDS: ClassVar = {"fog_coef": (0.05, 1.0)}
    PARAM_LIMITS: ClassVar = {
        "fps": (1.0, 1000.0),
        "spawn_per_s": (0.0, 10.0),
        "growth_per_s": (0.0, 10.0),
        "run_radius": (1.0, 10.0),
        "run_speed": (0.0, 100.0),
        "merge_frac": (0.0, 1.0),
        "drop_count": (1, 400),
        "drop_radius": (0.005, 0.25),
        "contact_deg": (20.0, 90.0),
        "hfov_deg": (20.0, 170.0),
        "look_up": (0.0, 1.0),
        "defocus": (0.0, 0.05),
        "blur": (0.0, 0.1),
        "rim": (0.0, 1.0),
        "highlight": (0.0, 1.0),
    }
    CHOICES: ClassVar = {"mode": ("faithful", "refractive")}

    # -- persistent state (in the run: see EffectRun) -------------------------------------------
    def new_episode(self) -> _Lens:
        return _Lens()

    @property
    def keeps_time(self) -> bool:
        return self.persistent

    def wipe(self, run: EffectRun | None = None) -> None:
        """Wipe the lens of ``run`` (default: the effect's own run): every persistent droplet is gone
        (new ones land later). ``WeatherWrapper(...).run`` is the run of the wrapper's episode."""
        d = (self._own_run if run is None else run).episode.drops
        if d is not None:
            d.take(np.zeros(len(d.r), bool))

    @property
    def drops(self) -> np.ndarray:
        """Droplets of the own run's persistent mode as an ``(N, 3)`` array of ``x, y, radius`` (px)."""
        d = self._own_run.episode.drops
        if d is None:
            return np.empty((0, 3))
        return np.stack([d.x, d.y, d.r], axis=1)

    def _layout(self, h: int, w: int, rng: np.random.Generator) -> tuple[np.ndarray, int]:
        _, radius, centres = fog_layout(h, w, self.fog_coef, rng)
        return np.asarray(centres, dtype=np.float64).reshape(-1, 2), radius

    def _lens_layout(self, h: int, w: int, rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
        return drop_layout(h, w, rng, n, self.drop_radius, self.contact_deg)

    def _advance(self, shape: tuple[int, ...], rng: np.random.Generator, lens: _Lens) -> _Drops:
        """Initialise (first frame, new size) or move the persistent droplets on by one frame."""
        if self.mode == "refractive":
            return self._advance_lens(shape, rng, lens)
        h, w = shape[:2]
        d = lens.drops
        if d is None or d.shape != (h, w) or d.theta is not None:
            c, radius = self._layout(h, w, rng)
            d = lens.drops = _Drops((h, w), float(radius), len(c), c[:, 0].copy(), c[:, 1].copy(),
                                    np.full(len(c), float(radius)))
            return d
        dt = 1.0 / self.fps
        d.frames += 1
        d.r = d.r * (1.0 + self.growth_per_s * dt)
        n_new = int(rng.poisson(self.spawn_per_s * max(d.base_count, 1) * dt))
        if n_new:
            c, _ = self._layout(h, w, rng)
            if len(c):
                pick = c[rng.integers(0, len(c), size=n_new)]
                d.x = np.concatenate([d.x, pick[:, 0]])
                d.y = np.concatenate([d.y, pick[:, 1]])
                d.r = np.concatenate([d.r, d.base_radius * rng.uniform(0.5, 1.0, size=n_new)])
        running = d.r > self.run_radius * d.base_radius
        d.y = d.y + running * (self.run_speed * h * dt)
        keep = d.y - d.r <= h
        d.x, d.y, d.r = d.x[keep], d.y[keep], d.r[keep]
        self._merge(d)
        cap = 4 * max(d.base_count, 1) + 16
        if len(d.r) > cap:  # never reached with sensible parameters; bounds the cost
            keep = np.argsort(d.r)[-cap:]
            d.x, d.y, d.r = d.x[keep], d.y[keep], d.r[keep]
        return d

    def _advance_lens(self, shape: tuple[int, ...], rng: np.random.Generator, lens: _Lens) -> _Drops:
        """:meth:`_advance` of the refractive mode: the drops of full severity, shown when ``u < k``."""
        h, w = shape[:2]
        d = lens.drops
        if d is None or d.shape != (h, w) or d.theta is None:
            x, y, r, th, u = self._lens_layout(h, w, rng, self.drop_count)
            # a drop runs once it is run_radius times the largest radius of the distribution
            d = lens.drops = _Drops((h, w), self.drop_radius * h * 1.25, self.drop_count, x, y, r, theta=th, u=u)
            return d
        dt = 1.0 / self.fps
        d.frames += 1
        d.r = d.r * (1.0 + self.growth_per_s * dt)
        n_new = int(rng.poisson(self.spawn_per_s * d.base_count * dt))
        if n_new:
            x, y, r, th, u = self._lens_layout(h, w, rng, n_new)
            r = r * rng.uniform(0.4, 0.8, size=n_new)
            for name, new in zip(("x", "y", "r", "theta", "u"), (x, y, r, th, u), strict=True):
                setattr(d, name, np.concatenate([getattr(d, name), new]))
        running = d.r > self.run_radius * d.base_radius
        d.y = d.y + running * (self.run_speed * h * dt)
        d.take(d.y - d.r <= h)
        self._merge(d)
        cap = 4 * d.base_count + 16
        if len(d.r) > cap:  # never reached with sensible parameters; bounds the cost
            d.take(np.argsort(d.r)[-cap:])
        return d

    def _merge(self, d: _Drops) -> None:
        if self.merge_frac <= 0:
            return
        for _ in range(len(d.r)):
            n = len(d.r)
            if n < 2:
                return
            dist = np.hypot(d.x[:, None] - d.x[None, :], d.y[:, None] - d.y[None, :])
            gap = dist - self.merge_frac * (d.r[:, None] + d.r[None, :])
            gap[np.arange(n), np.arange(n)] = np.inf
            i, j = np.unravel_index(int(np.argmin(gap)), gap.shape)
            if gap[i, j] >= 0:
                return
            a_i, a_j = d.r[i] ** 2, d.r[j] ** 2
            d.x[i] = (a_i * d.x[i] + a_j * d.x[j]) / (a_i + a_j)
            d.y[i] = (a_i * d.y[i] + a_j * d.y[j]) / (a_i + a_j)
            d.r[i] = math.sqrt(a_i + a_j)
            if d.theta is not None and d.u is not None:  # the merged drop is shown when either was (u is set with theta)
                d.u[i] = min(d.u[i], d.u[j])
            d.take(np.arange(n) != j)

    # -- sampling ----------------------------------------------------------------------------
    def _sample_frame(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any) -> Any:
        """The frame's discs (:class:`DiscDraw`) or drops (:class:`LensDraw`); the persistent mode
        moves the episode's drops on (a fresh lens when there is no episode)."""
        h, w = shape[:2]
        if self.persistent:
            d = self._advance(shape, rng, episode if episode is not None else _Lens())
            if self.mode == "refractive":
                assert d.theta is not None and d.u is not None  # the refractive mode draws both
                return LensDraw(d.x.copy(), d.y.copy(), d.r.copy(), d.theta.copy(), d.u.copy())
            return DiscDraw(np.rint(np.stack([d.x, d.y], axis=1)).astype(np.int64), np.rint(d.r).astype(np.int64))
        if self.mode == "refractive":
            return LensDraw(*self._lens_layout(h, w, rng, self.drop_count))
        _, radius, centres = fog_layout(h, w, self.fog_coef, rng)
        return DiscDraw(centres, [radius] * len(centres))

    # -- rendering ---------------------------------------------------------------------------
    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        if isinstance(draw, LensDraw):  # refractive: drops with u < k shown, radii scaled by (1 + k) / 2
            show = draw.u < self.k
            render_lens_drops(img, draw.x[show], draw.y[show], draw.r[show] * (0.5 + 0.5 * self.k),
                              draw.theta[show], out, hfov_deg=self.hfov_deg, look_up=self.look_up,
                              defocus=self.defocus, blur=self.blur, rim=self.rim, highlight=self.highlight)
            return
        render_discs(img, draw.centres, draw.radii, self.k * self.fog_coef, out)
