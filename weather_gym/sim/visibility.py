"""Ground truth without rendering: which cones the camera sees, computed from geometry.

The cone mesh the renderer draws (square base plate + frustum, :func:`weather_gym.sim.meshes.cone_dimensions`)
is projected through the pinhole camera (the same intrinsics, mount pose and clipping planes as the
rendered frame). Each cone's silhouette is modelled column by column: the frustum is a trapezoid from
its flat top to the plate, the plate a band across its full projected width. Cones stand on a flat
ground seen from above, so a nearer cone is always lower in the image; occlusion is then a per-column
"skyline": going from near to far, a cone is visible in a column only above the tops of the nearer
cones there. What is left gives, per visible cone, the same fields as the rendered ground truth
(``weather_gym.sim.camera``): the visible box (xyxy, pixel edges), class, cone id, range, bearing and
the number of visible pixels (pixel centres inside the silhouette, as a rasterizer counts them).

Knocked (tilted) cones are boxed by their projected corners and counted as that box.
What the model leaves out: anything but cones hiding cones (the world has nothing else standing);
silhouette details below a pixel. ``tests/sim/test_visibility.py`` measures the agreement with the
rendered ground truth on real laps.

Example:
    >>> import numpy as np
    >>> from weather_gym.camera import CameraConfig
    >>> from weather_gym.sim.visibility import visible_cones
    >>> cam = CameraConfig(width=160, height=90)
    >>> xy = np.array([[5.0, 0.0], [6.0, 0.0], [5.0, 30.0]])        # ahead, just behind it, far left
    >>> gt = visible_cones(cam, eye=(0.0, 0.0, 1.0), heading=0.0, pitch=np.radians(4.0),
    ...                    cone_xy=xy, classes=np.array([0, 1, 0]))
    >>> gt["cone_ids"].tolist(), gt["pixels"].tolist()   # the cone behind shows only its upper part
    ([0, 1], [12, 4])
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from weather_gym.camera import CameraConfig
from weather_gym.cone_arrays import ConeArrays
from weather_gym.cone_spec import CONE_BASE_M, CONE_CLASSES, CONE_HEIGHT_M
from weather_gym.sim.meshes import cone_dimensions

__all__ = ["visible_cones", "empty_ground_truth"]

_DIMS = [cone_dimensions(CONE_HEIGHT_M[c], CONE_BASE_M[c]) for c in CONE_CLASSES]
_HEIGHT = np.array([d["height"] for d in _DIMS])
_PLATE_HALF = np.array([d["plate_half"] for d in _DIMS])
_PLATE_H = np.array([d["plate_h"] for d in _DIMS])
_R0 = np.array([d["r0"] for d in _DIMS])
_R1 = np.array([d["r1"] for d in _DIMS])
_CORNERS = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
_RADIUS = _PLATE_HALF * math.sqrt(2.0)  # the plate's half-diagonal: a cone fits in this circle
_FACE_SIGN = np.array([[1.0], [-1.0]])
_LEFT_RIGHT = (np.array([12, 13]), np.array([13, 12]))
_BOX_SIGN = np.array([-1.0, 1.0, -1.0, 1.0])
_XYXY = np.array([0, 2, 1, 3])
_TWO = np.arange(2)[None, :, None]
_min, _max = np.minimum.reduce, np.maximum.reduce  # ufunc reductions: no Python wrapper per call


def _template() -> np.ndarray:
    """Key points per class (4, 14, 3) about the mesh origin; the top disc's (8-11) and the frustum
    bottom's (12-13) horizontal offsets depend on the view and are filled in per call."""
    t = np.zeros((len(CONE_CLASSES), 14, 3))
    t[:, 0:4, :2] = _CORNERS[None] * _PLATE_HALF[:, None, None]
    t[:, 4:8, :2] = t[:, 0:4, :2]
    t[:, 4:8, 2] = _PLATE_H[:, None]
    t[:, 8:12, 2] = _HEIGHT[:, None]
    t[:, 12:14, 2] = _PLATE_H[:, None]
    return t


_TEMPLATE = _template()


def empty_ground_truth() -> ConeArrays:
    """Ground truth of a frame without visible cones."""
    return ConeArrays(boxes=np.zeros((0, 4), np.float32), classes=np.zeros((0,), np.int64),
                      cone_ids=np.zeros((0,), np.int64), ranges=np.zeros((0,), np.float32),
                      bearings=np.zeros((0,), np.float32), pixels=np.zeros((0,), np.int64))


def _camera_axes(heading: float, pitch: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward, right and up unit vectors of a camera with ``heading`` (yaw) and downward ``pitch``."""
    ch, sh, cp, sp = math.cos(heading), math.sin(heading), math.cos(pitch), math.sin(pitch)
    fwd = np.array([ch * cp, sh * cp, -sp])
    right = np.array([sh, -ch, 0.0])
    up = np.array([ch * sp, sh * sp, cp])
    return fwd, right, up


def visible_cones(camera: CameraConfig, eye, heading: float, pitch: float, cone_xy: np.ndarray,
                  classes: np.ndarray, *, tilted: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = None
                  ) -> ConeArrays:
    """The cones ``camera`` sees from ``eye`` (x, y, z) looking along ``heading`` pitched down by ``pitch``.

    Args:
        cone_xy: (N, 2) cone positions on the ground; classes: (N,) class ids.
        tilted: cone index -> (mesh origin (3,), rotation matrix (3, 3)) for knocked cones.

    Returns the same ``ConeArrays`` fields as the rendered ground truth, sorted by cone id.
    """
    cam = camera
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    xy = np.asarray(cone_xy, dtype=np.float64).reshape(-1, 2)
    cls = np.asarray(classes, dtype=np.int64).reshape(-1)
    ch, sh, cp, sp = math.cos(heading), math.sin(heading), math.cos(pitch), math.sin(pitch)
    # the rows of (right, up, fwd) as columns (see _camera_axes), built from floats in one call
    axes = np.array([[sh, ch * sp, ch * cp], [-ch, sh * sp, sh * cp], [0.0, cp, -sp]])
    fwd, right = axes[:, 2], axes[:, 0]
    fx, fy, cx, cy, near, far = cam.fx, cam.fy, cam.cx, cam.cy, cam.near, cam.far
    width, height = int(cam.width), int(cam.height)

    # cull: in front, before the far plane, inside the field of view (of its base or its top,
    # whichever is deeper along the pitched optical axis)
    d = xy - eye[:2]
    z_flat = d @ fwd[:2]
    z_deep = z_flat + np.maximum(-eye[2] * fwd[2], (_HEIGHT[cls] - eye[2]) * fwd[2])
    radius = _RADIUS[cls]
    keep = (z_deep + radius > near) & (z_flat - radius < far) & (
        np.abs(d @ right[:2]) - radius < (z_deep + radius) * (0.5 * width / fx))
    if tilted:
        keep[list(tilted)] = True  # knocked cones may have slid or rolled anywhere: always projected
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return empty_ground_truth()
    c = cls[idx]
    k = idx.size

    # key points (K, 14, 3) relative to the mesh origin: 4 bottom and 4 top corners of the plate, the
    # top disc's extremes (left, right, near, far: it is tiny), the frustum bottom's extremes seen from
    # the eye (perpendicular to the line of sight, where a circle's silhouette is widest)
    fwd_h = fwd[:2] / max(math.hypot(fwd[0], fwd[1]), 1e-9)
    template = _TEMPLATE.copy()
    rx, ry, hx, hy = float(right[0]), float(right[1]), float(fwd_h[0]), float(fwd_h[1])
    template[:, 8:12, :2] = np.array([[rx, ry], [-rx, -ry], [-hx, -hy], [hx, hy]])[None] * _R1[:, None, None]
    pts = template[c]
    los = d[idx]
    perp = np.empty((k, 2))
    np.negative(los[:, 1], out=perp[:, 0])
    perp[:, 1] = los[:, 0]
    perp *= (_R0[c] / np.maximum(np.hypot(los[:, 0], los[:, 1]), 1e-9))[:, None]
    pts[:, 12, :2] = perp
    np.negative(perp, out=pts[:, 13, :2])
    origin = np.zeros((k, 3))
    origin[:, :2] = los
    origin[:, 2] = -eye[2]
    upright = np.ones(k, dtype=bool)
    if tilted:
        pos = {int(i): j for j, i in enumerate(idx)}
        for i, (org, rot) in tilted.items():
            j = pos[int(i)]
            rot = np.asarray(rot, dtype=np.float64).reshape(3, 3)
            origin[j] = np.asarray(org, dtype=np.float64).reshape(3) - eye
            pts[j] = pts[j] @ rot.T
            upright[j] = rot[2, 2] > math.cos(math.radians(3.0))  # standing (slid, not tipped)
    pts += origin[:, None, :]
    cam_xyz = pts @ axes
    zc = cam_xyz[..., 2]
    z_min = _min(zc, axis=1)
    in_front = (z_min > near) & (z_min < far)  # every key point beyond the near plane, one before the far
    zc = np.maximum(zc, near)
    u = cx + fx * cam_xyz[..., 0] / zc
    v = cy - fy * cam_xyz[..., 1] / zc

    # silhouette parameters per cone (pixels): its box; the flat top; the frustum's sides from the
    # top disc to the plate; the plate's upper outline (top face) and lower outline (bottom face),
    # each: leftmost corner -> highest / lowest corner -> rightmost corner
    u1, u2 = _min(u[:, :12], axis=1), _max(u[:, :12], axis=1)
    v1 = _min(v[:, :12], axis=1)
    rows = np.arange(k)[:, None]
    base = np.where(u[:, 12:13] <= u[:, 13:14], *_LEFT_RIGHT)  # (K, 2): left, right extreme
    ub, vb = u[rows, base], v[rows, base]
    # every per-cone parameter of the column stage in one (K, 11, 2) array, gathered per column in
    # one indexing: (v1, upright), (tl, tr), ub, side, then the plate outlines' u1, u2, v1, v2, s01,
    # s12, s23 (each: bottom face, top face)
    par = np.empty((k, 11, 2))
    t_lr = par[:, 1]
    tl, tr = np.minimum(u[:, 8], u[:, 9], out=t_lr[:, 0]), np.maximum(u[:, 8], u[:, 9], out=t_lr[:, 1])
    # plate outlines: the lower chain of the bottom face and the upper chain of the top face (its v
    # negated, so both are "the largest v"), through the face's corners sorted by u: corners off
    # the chain are lifted onto the chord between the outer two (the face is convex)
    uq = u[:, :8].reshape(k, 2, 4)  # [bottom face, top face]
    vq = v[:, :8].reshape(k, 2, 4) * _FACE_SIGN
    by_u = np.argsort(uq, axis=2)
    sel = (rows[:, :, None], _TWO, by_u)  # = take_along_axis(., by_u, axis=2)
    uq, vq = uq[sel], vq[sel]
    with np.errstate(divide="ignore", invalid="ignore"):
        chord = (vq[..., 3:] - vq[..., :1]) / (uq[..., 3:] - uq[..., :1])
        chord = np.where(np.isfinite(chord), chord, 0.0)
        vq[..., 1:3] = np.maximum(vq[..., 1:3], vq[..., :1] + chord * (uq[..., 1:3] - uq[..., :1]))
        slope = (vq[..., 1:] - vq[..., :-1]) / (uq[..., 1:] - uq[..., :-1])  # (K, 2, 3)
        slope = np.where(np.isfinite(slope), slope, 0.0)
        side = np.where(tl[:, None] - ub[:, :1] > 0, (vb - v1[:, None]) / np.abs(t_lr - ub), 0.0)
    side[:, 1] = np.where(ub[:, 1] > tr, side[:, 1], 0.0)

    # pixel columns whose centre lies inside [u1, u2], clipped to the image; cones ordered nearest
    # first (lowest point of the plate), so that within a column the pairs run from near to far
    bottom_low = _max(vq[:, 0], axis=1)
    j_lo = np.maximum(np.ceil(u1 - 0.5), 0).astype(np.int64)
    n_cols = np.minimum(np.floor(u2 - 0.5), width - 1).astype(np.int64) - j_lo + 1
    n_cols = np.where(in_front & (v1 < height) & (bottom_low > 0), np.maximum(n_cols, 0), 0)
    near_first = np.argsort(-bottom_low, kind="stable")
    near_first = near_first[n_cols[near_first] > 0]
    if near_first.size == 0:
        return empty_ground_truth()
    widths = n_cols[near_first]
    m = int(np.add.reduce(widths))
    starts = np.cumsum(widths) - widths
    slot = np.repeat(np.arange(near_first.size), widths)
    cone = near_first[slot]
    col = j_lo[cone] + (np.arange(m) - starts[slot])
    par[:, 0, 0] = v1
    par[:, 0, 1] = upright
    par[:, 2] = ub
    par[:, 3] = side
    par[:, 4:6] = uq[..., 1:3].transpose(0, 2, 1)  # each plate face's outline: u1, u2, v1, v2, s01, s12, s23
    par[:, 6:8] = vq[..., 1:3].transpose(0, 2, 1)
    par[:, 8:11] = slope.transpose(0, 2, 1)
    q = par[cone]  # (M, 11, 2)
    vt, up_, ptl, ptr, pbl, pbr, psl, psr = q[:, 0, 0], q[:, 0, 1], *q[:, 1:4].reshape(m, 6).T
    uc = col + 0.5

    # the silhouette in each column: top = min(frustum, plate top face), bottom = plate bottom face
    frustum_top = np.where(uc < ptl, vt + psl * (ptl - uc), np.where(uc > ptr, vt + psr * (uc - ptr), vt))
    frustum_top[(uc < pbl) | (uc > pbr)] = np.inf
    uc2 = uc[:, None]
    o_u1, o_u2, o_v1, o_v2, o_s01, o_s12, o_s23 = q[:, 4:].transpose(1, 0, 2)  # each (M, 2)
    du1 = uc2 - o_u1
    chain = np.where(uc2 < o_u1, o_v1 + o_s01 * du1, np.where(uc2 < o_u2, o_v1 + o_s12 * du1, o_v2 + o_s23 * (uc2 - o_u2)))
    bottom = chain[:, 0]
    top = np.where(up_ > 0, np.minimum(frustum_top, -chain[:, 1]), vt)

    # occlusion: going near to far in each column, a cone shows only above the nearer cones' tops
    order = np.argsort(col, kind="stable")
    col_s = col[order]
    new_col = np.empty(m, dtype=bool)
    new_col[0] = True
    np.not_equal(col_s[1:], col_s[:-1], out=new_col[1:])
    shift = np.cumsum(new_col) * (4.0 * (height + 1) + 4.0 * _max(np.abs(top)))
    running = np.minimum.accumulate(top[order] - shift) + shift
    sky = np.empty(m)
    sky[order[1:]] = np.where(new_col[1:], np.inf, running[:-1])
    sky[order[0]] = np.inf

    row_a = np.ceil(np.maximum(top, 0.0) - 0.5)
    row_b = np.ceil(np.minimum(np.minimum(bottom, sky), float(height)) - 0.5)
    count = np.maximum(row_b - row_a, 0.0)
    seen = count > 0
    never = -float(width + height + 10)
    extents = np.empty((m, 5))
    np.negative(col, out=extents[:, 0], casting="unsafe")
    np.add(col, 1, out=extents[:, 1], casting="unsafe")
    np.negative(row_a, out=extents[:, 2])
    extents[:, 3] = row_b
    np.copyto(extents[:, :4], never, where=~seen[:, None])
    extents[:, 4] = count
    ext = np.maximum.reduceat(extents, starts, axis=0)
    pixels = np.add.reduceat(count, starts)
    vis = pixels > 0
    if not np.logical_or.reduce(vis):
        return empty_ground_truth()
    ids = idx[near_first[vis]]
    by_id = np.argsort(ids)
    ids = ids[by_id]
    ext = ext[vis][by_id]
    boxes = (ext[:, :4] * _BOX_SIGN + 0.0).astype(np.float32)[:, _XYXY]  # (+0: no -0.0)
    dxy = d[ids]
    bearings = (np.arctan2(dxy[:, 1], dxy[:, 0]) - heading + np.pi) % (2 * np.pi) - np.pi
    return ConeArrays.trusted({"boxes": boxes, "classes": cls[ids], "cone_ids": ids,
                               "ranges": np.hypot(dxy[:, 0], dxy[:, 1]).astype(np.float32),
                               "bearings": bearings.astype(np.float32), "pixels": pixels[vis][by_id].astype(np.int64)})
