"""The perception surrogate model: fitted from logs, saved as a small validated ``.npz``.

One *point* per weather condition and fitted ``k`` (clear is ``("clear", 0)``, the ``k = 0`` end of
every condition); between points every parameter is interpolated linearly in ``k`` (logits,
quantiles, rates; false-positive rows as a mixture), beyond the last fitted ``k`` nothing is
extrapolated (an :class:`~weather_gym.core.errors.InputError`). Each point holds:

* **detection probability**: logistic regression on a linear B-spline ("hat") basis of range,
  |bearing|, log box height, visibility and crowding (the largest IoU of the cone's box with
  another cone's: what non-maximum suppression merges), plus the class (``coef``; L2-penalised
  maximum likelihood with scipy's L-BFGS; :mod:`~weather_gym.surrogate.fitting`);
* **loose detections**: a cone not detected may be boxed a little off (IoU 0.1-0.5: a scoring
  miss plus a false positive near the cone): their probability (``coef_loose``, the same basis),
  range/bearing error and score quantiles, and box offsets (``loose_box_d``);
* **time correlation**: a per-cone two-state Markov chain with persistence ``rho``:
  P(detected | detected before) = p + rho (1 - p), P(detected | missed before) = p (1 - rho), so a
  cone keeps its marginal p; ``rho`` by maximum likelihood on consecutive frames of the same cone
  (the empirical P(miss | miss) and P(miss | detected) are kept for the report);
* **class confusion** ``confusion[range bin, true, reported]`` (rows sum to 1; a little smoothing to
  the diagonal) of cones standing clear of others, ``confusion_crowded`` of crowded ones (crowding
  above :data:`CROWDED`: a cone partly behind or beside another is reported in the wrong class an
  order of magnitude more often), and ``confusion_loose`` of the loose detections;
* **range and bearing errors** (reported - true) as 41 quantiles per range bin
  (:data:`ERR_RANGE_EDGES`); **score** quantiles of true detections;
* **part detections**: a false positive whose box centre lies inside a cone's box but overlaps it by
  less than the loose IoU (a box on a near cone's stripe, on one cone of a pair, or on part of a far
  one) belongs to that cone, detected or not: its probability per cone (``coef_part``, the same
  basis), and up to :data:`MAX_FP_ROWS` logged ones (box relative to the cone's box, in units of its
  height; class, score, range and bearing error) resampled as they are. They scale with the cones in
  view, so a track with fewer or farther cones gets fewer, as the detector does;
* **false positives** away from every cone: count per frame, negative binomial by moments (Poisson
  when not over-dispersed), and up to :data:`MAX_FP_ROWS` logged ones (range, bearing, class,
  score, box) resampled as they are: where they appear and what they look like.

The shipped model, loaded and validated:
    >>> model = load_model()
    >>> "clear" in model.conditions()
    True
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core._io import atomic_file, check_output
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.surrogate.camera import box_factor, fitted_input_size
from weather_gym.surrogate.conditions import (
    condition_defaults,
    condition_of,
    effect_params,
    fallback_note,
    split_nominal,
)
from weather_gym.surrogate.fitting import (
    CONFUSION_PRIOR,
    L2,
    MAX_FP_ROWS,
    MIN_BIN_ROWS,
    fit_logistic,
    fit_point,
)
from weather_gym.surrogate.log import loose_matches, part_matches, read_npz
from weather_gym.surrogate.point import (
    BEARING_KNOTS,
    CROWD_KNOTS,
    CROWDED,
    ERR_RANGE_EDGES,
    LOGH_KNOTS,
    N_CLASSES,
    N_COEF,
    QUANTILES,
    RANGE_KNOTS,
    VIS_KNOTS,
    Point,
    _mix,
    crowding,
    crowding_column,
    design,
    hat_terms,
)

__all__ = ["MODEL_SCHEMA", "SHIPPED_MODEL", "SurrogateModel", "Point", "design", "fit_logistic", "fit_point",
           "fit", "save_model", "load_model", "ERR_RANGE_EDGES", "QUANTILES", "CROWDED", "crowding", "hat_terms",
           "crowding_column", "CONFUSION_PRIOR", "L2", "MAX_FP_ROWS", "MIN_BIN_ROWS"]

_CAMERA_FIELDS = frozenset(f.name for f in fields(CameraConfig))

MODEL_SCHEMA = 1
SHIPPED_MODEL = Path(__file__).with_name("models") / "shipped.npz"


@dataclass
class SurrogateModel:
    """Fitted points per condition (``points[condition]``: a list of ``(k, Point)`` sorted by k)."""

    clear: Point
    points: dict[str, list[tuple[float, Point]]]
    effects: dict[str, dict[str, Any]]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def camera_size(self) -> tuple[int, int] | None:
        cam = self.meta.get("camera") or {}
        return (int(cam["width"]), int(cam["height"])) if "width" in cam and "height" in cam else None

    def conditions(self) -> list[str]:
        return ["clear", *self.points]

    def box_factor(self, width: int, height: int) -> float:
        """What a box height in pixels of a ``width`` x ``height`` camera is multiplied by to be the model's
        box-height feature (the same size at the detector's input; 1.0 at the fitting camera, or when the
        model names no camera): :func:`weather_gym.surrogate.camera.box_factor`.

        Example:
            >>> from weather_gym.surrogate.model import load_model
            >>> load_model().box_factor(672, 376), round(load_model().box_factor(336, 188), 3)
            (1.0, 1.0)
        """
        size = self.camera_size
        if size is None or size == (int(width), int(height)):
            return 1.0  # (a model of a detector with another input, at its own camera, too)
        return box_factor(size, (int(width), int(height)), fit_input=fitted_input_size(self.meta))

    def range_factor(self, camera: Any) -> float:
        """A cone's range times this is the range at which it has the same box height in the fitting
        camera's pixels (the fitting camera's ``fy`` over ``camera``'s; 1.0 at the fitting camera, or when
        the model names no camera): the depth-ranging error is a matter of how many depth pixels the box
        holds, so the range error is drawn from that range's bin.

        Example:
            >>> from weather_gym.camera.config import CameraConfig
            >>> from weather_gym.surrogate.model import load_model
            >>> load_model().range_factor(CameraConfig()), load_model().range_factor(CameraConfig(width=336, height=188))
            (1.0, 2.0)
        """
        cam = self.meta.get("camera") or {}
        if "width" not in cam or "hfov_deg" not in cam:
            return 1.0
        fit = CameraConfig(**{k: v for k, v in cam.items() if k in _CAMERA_FIELDS})  # its fy, as the env's
        return 1.0 if fit.fy == camera.fy else fit.fy / float(camera.fy)

    def resolve(self, weather: Any) -> tuple[Point, str | None]:
        """The parameters for a weather spec and, when some of its effects have no fit here (the nominal
        presets: rain, fog, ...), the note that they are modelled as clear weather (else None); see
        :func:`weather_gym.surrogate.conditions.split_nominal`.

        Example:
            >>> from weather_gym.surrogate.model import load_model
            >>> point, note = load_model().resolve("rain@2")
            >>> point is load_model().clear, note.startswith("perception surrogate: no fit of weather effect rain")
            (True, True)
        """
        kept, dropped = split_nominal(weather, self.conditions())
        return self.point(kept), (fallback_note(dropped) if dropped else None)

    def point(self, weather: Any) -> Point:
        """The parameters for a weather spec (interpolated in k between fitted points).

        Example:
            >>> from weather_gym.surrogate.model import load_model
            >>> m = load_model()
            >>> 0 < m.point("droplets@3").fp_mean
            True
        """
        cond, k = condition_of(weather)
        if cond == "clear":
            return self.clear
        if cond not in self.points:
            raise InputError(f"the perception surrogate has no model of weather effect {cond!r}; this model has "
                             f"{', '.join(self.conditions())} (SurrogatePerceptionWrapper models an effect without a fit "
                             f"as clear weather, with a warning: SurrogateModel.resolve)")
        fitted = self.effects.get(cond, {})
        given = effect_params(weather)
        dflt = condition_defaults(cond)  # a parameter the effect gained after the fit: its default
        differ = sorted(key for key in set(fitted) | set(given)
                        if fitted.get(key, dflt.get(key)) != given.get(key, dflt.get(key)))
        if differ:
            raise InputError(f"the surrogate model's {cond} was fitted with other effect parameters "
                             f"({', '.join(f'{d}={fitted.get(d, dflt.get(d))!r}, given {given.get(d)!r}' for d in differ)}); "
                             f"refit it for this weather (docs/surrogate.md)")
        ks = [0.0] + [kk for kk, _ in self.points[cond]]
        pts = [self.clear] + [p for _, p in self.points[cond]]
        if k > ks[-1] + 1e-9:
            raise InputError(f"{cond} k={k:g} is beyond the surrogate's fitted range 0..{ks[-1]:g} (no extrapolation)")
        i = int(np.clip(np.searchsorted(ks, k, side="right") - 1, 0, len(ks) - 2))
        if abs(k - ks[i + 1]) < 1e-9:
            return pts[i + 1]
        return _mix(pts[i], pts[i + 1], (k - ks[i]) / (ks[i + 1] - ks[i]))

    def summary(self) -> str:
        """One line per fitted point: recall, P(miss | miss), P(miss | detected), rho, false positives per frame
        away from every cone, loose and part detections per frame."""
        lines = ["condition    k       frames  cones   recall  P(miss|miss) P(miss|det) rho    FP/frame loose/frame "
                 "part/frame"]
        rows = [("clear", 0.0, self.clear)] + [(c, k, p) for c, pts in self.points.items() for k, p in pts]
        for cond, k, p in rows:
            s = p.stats
            lines.append(f"{cond:<12} {k:<7.3f} {s.get('frames', 0):>6.0f} {s.get('cones', 0):>7.0f} "
                         f"{s.get('recall', math.nan):>6.3f}  {s.get('p_miss_after_miss', math.nan):>11.3f} "
                         f"{s.get('p_miss_after_detected', math.nan):>11.3f} {p.rho:.3f}  {p.fp_mean:>8.2f} "
                         f"{s.get('loose', math.nan) / max(s.get('frames', 1.0), 1.0):>11.2f} "
                         f"{s.get('part', math.nan) / max(s.get('frames', 1.0), 1.0):>10.2f}")
        return "\n".join(lines)


def fit(log: Any, sources: Sequence[str] = ()) -> SurrogateModel:
    """Fit a :class:`SurrogateModel` from a :class:`~weather_gym.surrogate.log.SurrogateLog` (all its conditions)."""
    groups: dict[tuple[str, float], list[int]] = {}
    effects: dict[str, dict[str, Any]] = {}
    for i, ep in enumerate(log.episodes):
        key = (str(ep["condition"]), round(float(ep["k"]), 6))
        groups.setdefault(key, []).append(i)
        if key[0] != "clear":
            params = effect_params(ep["weather"])
            if key[0] in effects and effects[key[0]] != params:
                raise InputError(f"surrogate fit: the logs have {key[0]} with different effect parameters; "
                                 f"fit one parameter set per condition")
            effects[key[0]] = params
    if ("clear", 0.0) not in groups:
        raise InputError("surrogate fit: the logs have no clear-weather episodes (the k = 0 point of every condition)")
    rng = np.random.default_rng(0)
    fitted: dict[tuple[str, float], Point] = {}
    for key, eps in sorted(groups.items()):
        sub = log.select(eps)
        lm = loose_matches(sub)
        fitted[key] = fit_point(sub.cones, sub.fps, sub.frames, rng, loose=lm, part=part_matches(sub, lm))
    points: dict[str, list[tuple[float, Point]]] = {}
    for (cond, k), p in sorted(fitted.items()):
        if cond != "clear":
            points.setdefault(cond, []).append((k, p))
    meta = {"schema": MODEL_SCHEMA, "camera": log.meta.get("camera", {}), "detector": log.meta.get("detector"),
            "tracks": sorted({str(e.get("track")) for e in log.episodes}), "sources": [os.path.basename(s) for s in sources],
            "episodes": len(log.episodes)}
    if log.meta.get("detector_input"):  # the detector's input at the fitting camera (surrogate.camera)
        meta["detector_input"] = [int(v) for v in log.meta["detector_input"]]
    return SurrogateModel(clear=fitted[("clear", 0.0)], points=points, effects=effects, meta=meta)


# ------------------------------------------------------------------------------------------ file
def _point_arrays(prefix: str, p: Point) -> dict[str, np.ndarray]:
    out = {f"{prefix}/{name}": np.asarray(getattr(p, name), np.float32 if name == "fp_rows" else np.float64)
           for name in Point.ARRAYS}
    out[f"{prefix}/scalars"] = np.array([p.rho, p.fp_mean, p.fp_var])
    return out


def save_model(model: SurrogateModel, path: str | os.PathLike, *, overwrite: bool = False) -> str:
    """Write the model as one compressed ``.npz`` (arrays per point and a ``meta`` JSON)."""
    check_output(path, overwrite=overwrite, suffixes=(".npz",), what="surrogate model")
    arrays = _point_arrays("clear", model.clear)
    index = []
    for cond, pts in model.points.items():
        for j, (k, p) in enumerate(pts):
            arrays.update(_point_arrays(f"{cond}/{j}", p))
            index.append({"condition": cond, "k": k, "key": f"{cond}/{j}", "stats": p.stats})
    meta = {**model.meta, "schema": MODEL_SCHEMA, "points": index, "clear_stats": model.clear.stats,
            "effects": model.effects, "basis": {"range": RANGE_KNOTS.tolist(), "bearing": BEARING_KNOTS.tolist(),
                                                "log_box_h": LOGH_KNOTS.tolist(), "visibility": VIS_KNOTS.tolist(),
                                                "crowding": CROWD_KNOTS.tolist()},
            "err_range_edges": [float(x) for x in ERR_RANGE_EDGES[:-1]], "quantiles": len(QUANTILES)}
    arrays["meta"] = np.array(json.dumps(meta))
    with atomic_file(path, "wb", overwrite=overwrite, encoding=None) as f:
        np.savez_compressed(f, **arrays)  # type: ignore[arg-type]  # numpy's stubs: **kwds typed like allow_pickle
    return str(path)


_QSHAPE = (len(ERR_RANGE_EDGES) - 1, len(QUANTILES))
_CSHAPE = (len(ERR_RANGE_EDGES) - 1, N_CLASSES, N_CLASSES)
_SHAPES = {"coef": (N_COEF,), "coef_loose": (N_COEF,), "confusion": _CSHAPE, "confusion_loose": _CSHAPE,
           "confusion_crowded": _CSHAPE, "coef_part": (N_COEF,),
           "range_err_q": _QSHAPE, "bearing_err_q": _QSHAPE, "loose_range_err_q": _QSHAPE,
           "loose_bearing_err_q": _QSHAPE, "score_q": (len(QUANTILES),), "loose_score_q": (len(QUANTILES),),
           "scalars": (3,)}
_ROWS = {"fp_rows": 8, "det_box_d": 4, "loose_box_d": 4, "part_rows": 8}


def _read_point_arrays(data: dict[str, np.ndarray], prefix: str, where: str) -> dict[str, np.ndarray]:
    """The arrays of the point ``prefix`` (float64, by name), each checked for its shape and finite values."""
    arrays = {}
    for name in (*Point.ARRAYS, "scalars"):
        key = f"{prefix}/{name}"
        if key not in data and name in Point.OPTIONAL:
            continue
        if key not in data:
            raise FileFormatError(f"{where}: missing array {key!r}")
        a = np.asarray(data[key], np.float64)
        if name in _ROWS:
            want: Any = f"(M, {_ROWS[name]})"
            shape_ok = a.ndim == 2 and a.shape[1] == _ROWS[name]
        else:
            want = _SHAPES[name]
            shape_ok = a.shape == want
        if not shape_ok:
            raise FileFormatError(f"{where}: array {key!r} has shape {a.shape}, expected {want}")
        if not np.all(np.isfinite(a)):
            raise FileFormatError(f"{where}: array {key!r} has non-finite values")
        arrays[name] = a
    return arrays


def _load_point(data: dict[str, np.ndarray], prefix: str, where: str, stats: Any) -> Point:
    arrays = _read_point_arrays(data, prefix, where)
    for name in ("confusion", "confusion_loose", "confusion_crowded"):
        if name not in arrays:
            continue
        conf = arrays[name]
        if np.any(conf < 0) or not np.allclose(conf.sum(axis=-1), 1.0, atol=1e-6):
            raise FileFormatError(f"{where}: {prefix}/{name} must have non-negative rows summing to 1")
    for name in ("range_err_q", "bearing_err_q", "score_q", "loose_range_err_q", "loose_bearing_err_q", "loose_score_q"):
        if np.any(np.diff(arrays[name], axis=-1) < -1e-9):
            raise FileFormatError(f"{where}: {prefix}/{name} quantiles must be non-decreasing")
    rho, fp_mean, fp_var = arrays["scalars"]
    if not (0.0 <= rho < 1.0) or fp_mean < 0 or fp_var < 0:
        raise FileFormatError(f"{where}: {prefix}/scalars (rho {rho}, fp_mean {fp_mean}, fp_var {fp_var}) out of range: "
                              f"need 0 <= rho < 1 and non-negative rates")
    rows = arrays["fp_rows"]
    if len(rows) and (rows[:, 2].min() < 0 or rows[:, 2].max() >= N_CLASSES):
        raise FileFormatError(f"{where}: {prefix}/fp_rows has classes outside 0..{N_CLASSES - 1}")
    prows = arrays.get("part_rows")
    if prows is not None and len(prows) and (prows[:, 4].min() < 0 or prows[:, 4].max() >= N_CLASSES):
        raise FileFormatError(f"{where}: {prefix}/part_rows has classes outside 0..{N_CLASSES - 1}")
    if fp_mean > 0 and not len(rows):
        raise FileFormatError(f"{where}: {prefix} has false positives per frame {fp_mean} but no false-positive rows")
    for name in ("det_box_d", "loose_box_d"):
        if not len(arrays[name]):
            raise FileFormatError(f"{where}: {prefix}/{name} has no rows")
    named = {n: arrays.get(n) for n in Point.ARRAYS}
    return Point(**named, rho=float(rho), fp_mean=float(fp_mean), fp_var=float(fp_var),  # type: ignore[arg-type]  # arrays checked above
                 stats=dict(stats) if isinstance(stats, dict) else {})


_CACHE: dict[tuple[str, float, int], SurrogateModel] = {}


def load_model(path: str | os.PathLike | None = None) -> SurrogateModel:
    """Read and validate a model (None: the shipped one); :class:`FileFormatError` naming what is wrong.

    Loaded models are cached by path, modification time and size (the envs of a vector env share one).
    """
    p = os.fspath(path) if path is not None else os.fspath(SHIPPED_MODEL)
    where = f"surrogate model {p}"
    if not os.path.isfile(p):
        raise MissingInputError(f"{where} does not exist")
    st = os.stat(p)
    key = (os.path.abspath(p), st.st_mtime, st.st_size)
    if key in _CACHE:
        return _CACHE[key]
    data, meta = read_npz(p, where, "surrogate model", MODEL_SCHEMA)
    index = meta.get("points")
    if not isinstance(index, list):
        raise FileFormatError(f"{where}: meta 'points' must be a list")
    clear = _load_point(data, "clear", where, meta.get("clear_stats"))
    points: dict[str, list[tuple[float, Point]]] = {}
    for entry in index:
        if not (isinstance(entry, dict) and isinstance(entry.get("condition"), str) and isinstance(entry.get("key"), str)
                and isinstance(entry.get("k"), int | float) and 0 < entry["k"] <= 1):
            raise FileFormatError(f"{where}: a meta 'points' entry needs condition, key and k in (0, 1], got {entry!r}")
        points.setdefault(entry["condition"], []).append(
            (float(entry["k"]), _load_point(data, entry["key"], where, entry.get("stats"))))
    for cond, pts in points.items():
        pts.sort(key=lambda t: t[0])
        ks = [k for k, _ in pts]
        if len(set(ks)) != len(ks):
            raise FileFormatError(f"{where}: condition {cond!r} has the same k twice ({ks})")
    effects = meta.pop("effects", {})
    if not isinstance(effects, dict):
        raise FileFormatError(f"{where}: meta 'effects' must be a table")
    model = SurrogateModel(clear=clear, points=points, effects=effects, meta=meta)
    _CACHE[key] = model
    return model
