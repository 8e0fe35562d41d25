"""Ground truth without rendering: which cones the camera sees, computed from geometry.

The cone mesh the renderer draws (square base plate + frustum, :func:`weather_gym.sim.meshes.cone_dimensions`)
is projected through the pinhole camera (the same intrinsics, mount pose and clipping planes as the
rendered frame). Each cone's silhouette is modelled column by column: the frustum is a trapezoid from
its flat top to the plate, the plate a band across its full projected width. Cones stand on a flat
ground seen from above, so a nearer cone is always lower in the image; occlusion is then a per-column
"skyline": going from near to far, a cone is visible in a column only above the tops of the nearer
cones there. What is left gives, per visible cone, the same fields as the rendered ground truth
(``weather_gym.sim.camera_sensor``): the visible box (xyxy, pixel edges), class, cone id, range, bearing and
the number of visible pixels (pixel centres inside the silhouette, as a rasterizer counts them).

Knocked (tilted) cones are boxed by their projected corners and counted as that box.
What the model leaves out: anything but cones hiding cones (the world has nothing else standing);
silhouette details below a pixel. ``tests/sim/test_visibility.py`` measures the agreement with the
rendered ground truth on real laps.

Example:
    >>> import numpy as np
    >>> from weather_gym.camera.config import CameraConfig
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

import numba
import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core._jit_cache import jit_cache
from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.cone_spec import CONE_BASE_M, CONE_CLASSES, CONE_HEIGHT_M
from weather_gym.sim.meshes import cone_dimensions

__all__ = ["visible_cones", "empty_ground_truth"]

_DIMS = [cone_dimensions(CONE_HEIGHT_M[c], CONE_BASE_M[c]) for c in CONE_CLASSES]
# per class: height, plate half-width, plate height, frustum radius at the plate, at the top
_SHAPE = np.array([[d["height"], d["plate_half"], d["plate_h"], d["r0"], d["r1"]] for d in _DIMS])
_UPRIGHT_COS = math.cos(math.radians(3.0))  # a knocked cone tilted less than this still stands (slid)
_NO_TILT = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)))


def empty_ground_truth() -> ConeArrays:
    """Ground truth of a frame without visible cones."""
    return ConeArrays(boxes=np.zeros((0, 4), np.float32), classes=np.zeros((0,), np.int64),
                      cone_ids=np.zeros((0,), np.int64), ranges=np.zeros((0,), np.float32),
                      bearings=np.zeros((0,), np.float32), pixels=np.zeros((0,), np.int64))


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
    ex, ey, ez = (float(t) for t in eye)
    xy = np.ascontiguousarray(cone_xy, dtype=np.float64).reshape(-1, 2)
    cls = np.ascontiguousarray(classes, dtype=np.int64).reshape(-1)
    if tilted:
        keys = sorted(tilted)
        tilt = (np.array(keys, np.int64),
                np.array([np.asarray(tilted[i][0], np.float64).reshape(3) for i in keys]),
                np.array([np.asarray(tilted[i][1], np.float64).reshape(3, 3) for i in keys]))
    else:
        tilt = _NO_TILT
    ids, boxes, ranges, bearings, pixels = _visible(
        ex, ey, ez, float(heading), float(pitch), float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy),
        float(cam.near), float(cam.far), int(cam.width), int(cam.height), xy, cls, *tilt, _SHAPE)
    if ids.size == 0:
        return empty_ground_truth()
    return ConeArrays.trusted({"boxes": boxes, "classes": cls[ids], "cone_ids": ids, "ranges": ranges,
                               "bearings": bearings, "pixels": pixels})


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _visible(ex, ey, ez, heading, pitch, fx, fy, cx, cy, near, far, width, height, xy, cls,  # noqa: C901 (one compiled loop)
             tilt_idx, tilt_org, tilt_rot, shape):  # pragma: no cover (compiled; tested through visible_cones)
    """The kernel of :func:`visible_cones`: (ids, boxes, ranges, bearings, pixels) of the visible cones."""
    n = xy.shape[0]
    ch, sh, cp, sp = math.cos(heading), math.sin(heading), math.cos(pitch), math.sin(pitch)
    # camera axes: right, up, forward (world frame)
    rx, ry, rz = sh, -ch, 0.0
    ux, uy, uz = ch * sp, sh * sp, cp
    fwx, fwy, fwz = ch * cp, sh * cp, -sp
    fh = max(math.hypot(fwx, fwy), 1e-9)
    hx, hy = fwx / fh, fwy / fh
    tpos = np.full(n, -1, np.int64)
    for t in range(tilt_idx.shape[0]):
        tpos[tilt_idx[t]] = t

    # cull: in front, before the far plane, inside the field of view (of its base or its top,
    # whichever is deeper along the pitched optical axis)
    half_fov = 0.5 * width / fx
    kept = np.empty(n, np.int64)
    k = 0
    for i in range(n):
        c = cls[i]
        dx, dy = xy[i, 0] - ex, xy[i, 1] - ey
        z_flat = dx * fwx + dy * fwy
        z_deep = z_flat + max(-ez * fwz, (shape[c, 0] - ez) * fwz)
        radius = shape[c, 1] * math.sqrt(2.0)  # the plate's half-diagonal: a cone fits in this circle
        if tpos[i] >= 0 or (z_deep + radius > near and z_flat - radius < far
                            and abs(dx * rx + dy * ry) - radius < (z_deep + radius) * half_fov):
            kept[k] = i
            k += 1

    # per kept cone: 14 key points projected (4 bottom and 4 top corners of the plate, the top disc's
    # extremes: left, right, near, far, and the frustum bottom's extremes seen from the eye,
    # perpendicular to the line of sight, where a circle's silhouette is widest), then the
    # silhouette's parameters (pixels): box, flat top, frustum sides, plate outlines
    pu = np.empty(14)
    pv = np.empty(14)
    p = np.empty((14, 3))
    uq = np.empty((2, 4))
    vq = np.empty((2, 4))
    j_lo = np.zeros(k, np.int64)
    n_cols = np.zeros(k, np.int64)
    bottom_low = np.empty(k)
    # per cone: v1, upright, tl, tr, ub_l, ub_r, side_l, side_r, then per plate face (bottom, top):
    # outline u1, u2, v1, v2, s01, s12, s23
    par = np.empty((k, 22))
    corners = ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0))
    for j in range(k):
        i = kept[j]
        c = cls[i]
        hgt, ph, plh, r0, r1 = shape[c, 0], shape[c, 1], shape[c, 2], shape[c, 3], shape[c, 4]
        lx, ly = xy[i, 0] - ex, xy[i, 1] - ey
        for q in range(4):
            p[q, 0] = corners[q][0] * ph
            p[q, 1] = corners[q][1] * ph
            p[q, 2] = 0.0
            p[q + 4, 0] = p[q, 0]
            p[q + 4, 1] = p[q, 1]
            p[q + 4, 2] = plh
        disc = ((rx, ry), (-rx, -ry), (-hx, -hy), (hx, hy))
        for q in range(4):
            p[8 + q, 0] = disc[q][0] * r1
            p[8 + q, 1] = disc[q][1] * r1
            p[8 + q, 2] = hgt
        s = r0 / max(math.hypot(lx, ly), 1e-9)
        p[12, 0], p[12, 1], p[12, 2] = -ly * s, lx * s, plh
        p[13, 0], p[13, 1], p[13, 2] = ly * s, -lx * s, plh
        t = tpos[i]
        upright = True
        if t >= 0:  # knocked: rotated about its mesh origin, wherever it slid or rolled
            ox, oy, oz = tilt_org[t, 0] - ex, tilt_org[t, 1] - ey, tilt_org[t, 2] - ez
            rot = tilt_rot[t]
            for q in range(14):
                a, b, z = p[q, 0], p[q, 1], p[q, 2]
                p[q, 0] = a * rot[0, 0] + b * rot[0, 1] + z * rot[0, 2]
                p[q, 1] = a * rot[1, 0] + b * rot[1, 1] + z * rot[1, 2]
                p[q, 2] = a * rot[2, 0] + b * rot[2, 1] + z * rot[2, 2]
            upright = rot[2, 2] > _UPRIGHT_COS
        else:
            ox, oy, oz = lx, ly, -ez
        z_min = np.inf
        for q in range(14):
            a, b, z = p[q, 0] + ox, p[q, 1] + oy, p[q, 2] + oz
            xc = a * rx + b * ry + z * rz
            yc = a * ux + b * uy + z * uz
            zc = a * fwx + b * fwy + z * fwz
            z_min = min(z_min, zc)
            zc = max(zc, near)
            pu[q] = cx + fx * xc / zc
            pv[q] = cy - fy * yc / zc
        in_front = near < z_min < far  # every key point beyond the near plane, one before the far
        u1, u2, v1 = pu[0], pu[0], pv[0]
        for q in range(1, 12):
            u1, u2, v1 = min(u1, pu[q]), max(u2, pu[q]), min(v1, pv[q])
        bl, br = (12, 13) if pu[12] <= pu[13] else (13, 12)  # the frustum bottom's left, right extreme
        ubl, ubr, vbl, vbr = pu[bl], pu[br], pv[bl], pv[br]
        tl, tr = min(pu[8], pu[9]), max(pu[8], pu[9])
        side_l = (vbl - v1) / abs(tl - ubl) if tl - ubl > 0 else 0.0
        side_r = (vbr - v1) / abs(tr - ubr) if tl - ubl > 0 and ubr > tr else 0.0
        # plate outlines: the lower chain of the bottom face and the upper chain of the top face (its
        # v negated, so both are "the largest v"), through the face's corners sorted by u: corners
        # off the chain are lifted onto the chord between the outer two (the face is convex)
        for f in range(2):
            sign = 1.0 if f == 0 else -1.0
            for q in range(4):  # insertion sort by u (stable)
                a, b = pu[4 * f + q], pv[4 * f + q] * sign
                r = q
                while r > 0 and uq[f, r - 1] > a:
                    uq[f, r], vq[f, r] = uq[f, r - 1], vq[f, r - 1]
                    r -= 1
                uq[f, r], vq[f, r] = a, b
            chord = (vq[f, 3] - vq[f, 0]) / (uq[f, 3] - uq[f, 0]) if uq[f, 3] != uq[f, 0] else 0.0
            if not math.isfinite(chord):
                chord = 0.0
            for q in (1, 2):
                vq[f, q] = max(vq[f, q], vq[f, 0] + chord * (uq[f, q] - uq[f, 0]))
            o = 8 + 7 * f
            par[j, o], par[j, o + 1], par[j, o + 2], par[j, o + 3] = uq[f, 1], uq[f, 2], vq[f, 1], vq[f, 2]
            for q in range(3):
                du = uq[f, q + 1] - uq[f, q]
                sl = (vq[f, q + 1] - vq[f, q]) / du if du != 0.0 else 0.0
                par[j, o + 4 + q] = sl if math.isfinite(sl) else 0.0
        par[j, 0], par[j, 1], par[j, 2], par[j, 3] = v1, 1.0 if upright else 0.0, tl, tr
        par[j, 4], par[j, 5], par[j, 6], par[j, 7] = ubl, ubr, side_l, side_r
        bottom_low[j] = max(max(vq[0, 0], vq[0, 1]), max(vq[0, 2], vq[0, 3]))
        # pixel columns whose centre lies inside [u1, u2], clipped to the image
        if in_front and v1 < height and bottom_low[j] > 0:
            lo = max(np.ceil(u1 - 0.5), 0.0)
            hi = min(np.floor(u2 - 0.5), width - 1.0)
            if hi >= lo:
                j_lo[j] = int(lo)
                n_cols[j] = int(hi) - int(lo) + 1

    # nearest first (lowest point of the plate); in each column a cone shows only above the tops
    # of the nearer cones there (the "skyline")
    order = np.argsort(-bottom_low, kind="mergesort")
    sky = np.full(width, np.inf)
    lo_col = np.full(k, width, np.int64)
    hi_col = np.full(k, -1, np.int64)
    lo_row = np.full(k, np.inf)
    hi_row = np.full(k, -np.inf)
    pixels = np.zeros(k, np.int64)
    for j in order:
        if n_cols[j] == 0:
            continue
        vt, up, ptl, ptr, pbl, pbr, psl, psr = (par[j, 0], par[j, 1], par[j, 2], par[j, 3], par[j, 4],
                                                par[j, 5], par[j, 6], par[j, 7])
        for col in range(j_lo[j], j_lo[j] + n_cols[j]):
            uc = col + 0.5
            if uc < pbl or uc > pbr:
                frustum_top = np.inf
            elif uc < ptl:
                frustum_top = vt + psl * (ptl - uc)
            elif uc > ptr:
                frustum_top = vt + psr * (uc - ptr)
            else:
                frustum_top = vt
            chain0, chain1 = 0.0, 0.0
            for f in range(2):
                o = 8 + 7 * f
                o_u1, o_u2, o_v1, o_v2 = par[j, o], par[j, o + 1], par[j, o + 2], par[j, o + 3]
                if uc < o_u1:
                    ch_ = o_v1 + par[j, o + 4] * (uc - o_u1)
                elif uc < o_u2:
                    ch_ = o_v1 + par[j, o + 5] * (uc - o_u1)
                else:
                    ch_ = o_v2 + par[j, o + 6] * (uc - o_u2)
                if f == 0:
                    chain0 = ch_
                else:
                    chain1 = ch_
            bottom = chain0
            top = min(frustum_top, -chain1) if up > 0 else vt
            above = sky[col]
            sky[col] = min(above, top)
            row_a = np.ceil(max(top, 0.0) - 0.5)
            row_b = np.ceil(min(min(bottom, above), float(height)) - 0.5)
            if row_b > row_a:
                pixels[j] += int(row_b - row_a)
                lo_col[j] = min(lo_col[j], col)
                hi_col[j] = max(hi_col[j], col + 1)
                lo_row[j] = min(lo_row[j], row_a)
                hi_row[j] = max(hi_row[j], row_b)

    m = 0
    for j in range(k):
        if pixels[j] > 0:
            m += 1
    ids = np.empty(m, np.int64)
    boxes = np.empty((m, 4), np.float32)
    ranges = np.empty(m, np.float32)
    bearings = np.empty(m, np.float32)
    pix = np.empty(m, np.int64)
    o = 0
    for j in range(k):  # kept is in cone-id order
        if pixels[j] == 0:
            continue
        i = kept[j]
        dx, dy = xy[i, 0] - ex, xy[i, 1] - ey
        ids[o] = i
        boxes[o, 0], boxes[o, 1] = lo_col[j], lo_row[j] + 0.0  # (+0: no -0.0)
        boxes[o, 2], boxes[o, 3] = hi_col[j], hi_row[j]
        ranges[o] = math.hypot(dx, dy)
        b = np.fmod(math.atan2(dy, dx) - heading + math.pi, 2.0 * math.pi)  # numpy's % on floats
        bearings[o] = (b + 2.0 * math.pi if b < 0.0 else b) - math.pi
        pix[o] = pixels[j]
        o += 1
    return ids, boxes, ranges, bearings, pix
