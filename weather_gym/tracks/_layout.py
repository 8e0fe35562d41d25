"""Track layouts from cones or from a centerline, as the fields of a :class:`~weather_gym.tracks.Track`
(plain dicts; :mod:`weather_gym.tracks` wraps them): a closed loop or an open lane from cone
positions, the skidpad sequence from its circles, and a ring of cones around a generated centerline
(private: no stable API; the polyline primitives are in :mod:`weather_gym.tracks._geometry`).

Example:
    >>> import numpy as np
    >>> from weather_gym.tracks._geometry import resample
    >>> t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    >>> line = resample(np.column_stack([20 * np.cos(t), 20 * np.sin(t)]), closed=True)
    >>> fields = ring_layout(line, 3.5, None, 6.0)
    >>> fields["event"], fields["closed"], round(float(fields["half_width_left"][0]), 2)
    ('trackdrive', True, 1.75)
"""

from __future__ import annotations

import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES as CONE_NAMES
from weather_gym.core.errors import InputError
from weather_gym.tracks._geometry import (
    STEP_M,
    cumulative_length,
    curvatures,
    fit_circle,
    half_widths,
    headings,
    mixed_edge_chain,
    offset,
    place_on,
    polyline_length,
    resample,
    signed_lateral,
    smooth,
    straightest_index,
)

# ---------------------------------------------------------------------------------------------
# layouts -> Track fields (plain dicts; weather_gym.tracks wraps them in a Track)

BLUE, YELLOW, ORANGE, BIG_ORANGE = 0, 1, 2, 3
START_OFFSET_M = 6.0
"""Default distance of the start pose behind the start line."""
LEAD_M = 5.0
"""Open centerlines begin this far behind the start pose."""
ACCEL_LENGTH_M = 75.0
SKIDPAD_STOP_M = 3.0  # the skidpad run ends this far (rear axle) before the cones closing the exit lane
SMOOTH_SIGMA_M = 2.0


def _orient_blue_left(line: np.ndarray, xy: np.ndarray, cls: np.ndarray, closed: bool) -> np.ndarray:
    lat, _ = signed_lateral(xy[cls == BLUE], line, closed)
    return line[::-1].copy() if np.median(lat) < 0 else line


def _groups_along(s: np.ndarray, gap: float) -> list[np.ndarray]:
    """Split sorted arc positions into groups separated by more than ``gap``."""
    order = np.argsort(s, kind="stable")
    cuts = np.nonzero(np.diff(s[order]) > gap)[0] + 1
    return [order[g] for g in np.split(order, cuts)] if len(s) else []


def layout_from_cones(xy: np.ndarray, cls: np.ndarray, start: tuple | None, where: str) -> dict:
    """Centerline, widths, start/finish of a trackdrive loop or an open (acceleration) lane."""
    side = np.where(cls == BLUE, 1.0, np.where(cls == YELLOW, -1.0, 0.0))
    bnd = side != 0
    mids, closed = mixed_edge_chain(xy[bnd], side[bnd])
    if len(mids) < 3:
        raise InputError(f"{where}: no blue cone faces a yellow cone: cannot find the track between them "
                         "(are the cones all on one line?)")
    line = _orient_blue_left(smooth(mids, closed, SMOOTH_SIGMA_M, debias=True), xy, cls, closed)
    # orange / big orange cones join the boundary on their side (those across the lane do not)
    lat, _ = signed_lateral(xy, line, closed)
    typical = float(np.median(np.abs(lat[bnd])))
    lateral_ok = np.abs(lat) > 0.6 * typical
    side = np.where(bnd, side, np.where(lateral_ok, np.sign(lat), 0.0))
    use = side != 0
    mids2, closed2 = mixed_edge_chain(xy[use], side[use])
    if len(mids2) >= len(mids):
        mids, closed = mids2, closed2
    line = _orient_blue_left(smooth(mids, closed, SMOOTH_SIGMA_M, debias=True), xy, cls, closed)
    _, s_cone = signed_lateral(xy, line, closed)
    start_xy = None if start is None else np.asarray(start[:2], dtype=float)
    big = np.nonzero(cls == BIG_ORANGE)[0]
    finish_s: float | None
    if closed:
        if len(big):
            groups = _groups_along(s_cone[big], gap=10.0)
            ref = xy[big].mean(axis=0) if start_xy is None else start_xy
            g = min(groups, key=lambda g: np.linalg.norm(xy[big[g]].mean(axis=0) - ref))
            line_xy = xy[big[g]].mean(axis=0)
        elif start_xy is not None:
            line_xy = start_xy
        else:
            line_xy = line[straightest_index(line, closed)]
        _, s0 = signed_lateral(line_xy[None], line, closed)
        line = resample(line, closed, start_s=float(s0[0]))
        length = polyline_length(line, closed)
        start_line_s, finish_s = 0.0, length
    else:
        if len(big):
            groups = _groups_along(s_cone[big], gap=3.0)
            start_line_s = float(s_cone[big[groups[0]]].max())
            finish_s = float(s_cone[big[groups[1]]].min()) if len(groups) > 1 else None
        else:
            start_line_s, finish_s = float(s_cone[bnd].min()), None
        if finish_s is None:
            finish_s = start_line_s + ACCEL_LENGTH_M
        s_start = start_line_s - START_OFFSET_M
        if start_xy is not None:
            s_start = float(signed_lateral(start_xy[None], line, closed)[1][0])
        back = max(0.0, LEAD_M - s_start)
        if back > 0:
            h = headings(line, closed)[0]
            pre = line[0] - np.outer(np.linspace(back, 0.0, max(int(back / STEP_M), 1) + 1)[:-1],
                                     [np.cos(h), np.sin(h)])
            line = resample(np.concatenate([pre, line]), closed)
        start_line_s += back
        finish_s += back
        length = polyline_length(line, closed)
        if finish_s > length + 1e-6:
            raise InputError(f"{where}: the lane ends {length - start_line_s:.1f} m after the start line; "
                             f"an open track needs big_orange finish cones or {ACCEL_LENGTH_M:.0f} m of lane")
    lat, s_cone = signed_lateral(xy, line, closed)
    hw = []
    for sign in (1.0, -1.0):
        members = np.nonzero(side == sign)[0]
        members = members[np.argsort(s_cone[members], kind="stable")]
        if closed and len(members) < 3:
            raise InputError(f"{where}: a closed track needs at least 3 cones on each side")
        hw.append(xy[members])
    hwl, hwr = half_widths(line, hw[0], hw[1], closed)
    return dict(centerline=line, closed=closed, event="trackdrive" if closed else "acceleration",
                half_width_left=hwl, half_width_right=hwr, start_line_s=start_line_s, finish_s=finish_s,
                start_pose=_start_pose(line, closed, start, start_line_s, where))


def _start_pose(line: np.ndarray, closed: bool, start: tuple | None, start_line_s: float,
                where: str) -> tuple[float, float, float]:
    s, length = cumulative_length(line, closed)
    h = np.unwrap(headings(line, closed))
    if start is None:
        q = (start_line_s - START_OFFSET_M) % length if closed else start_line_s - START_OFFSET_M
        x = np.interp(q, s, line[:, 0])
        y = np.interp(q, s, line[:, 1])
        yaw = float(np.interp(q, s, h))
        return (float(x), float(y), float(np.arctan2(np.sin(yaw), np.cos(yaw))))
    _, qs = signed_lateral(np.asarray(start[:2], dtype=float)[None], line, closed)
    along = float(np.interp(qs[0] % length if closed else qs[0], s, h))
    yaw = along if start[2] is None else float(start[2])
    if np.cos(yaw - along) < 0:
        raise InputError(f"{where}: car_start faces against the driving direction "
                         "(the driving direction keeps blue cones on the left)")
    return (float(start[0]), float(start[1]), float(np.arctan2(np.sin(yaw), np.cos(yaw))))


def skidpad_from_cones(xy: np.ndarray, cls: np.ndarray, start: tuple | None, where: str) -> dict:
    """The FS skidpad sequence: entry, 2 laps right circle, 2 laps left circle, exit."""
    big = xy[cls == BIG_ORANGE]
    if len(big) < 2 or start is None:
        raise InputError(f"{where}: a skidpad needs big_orange cones at the crossing and a car_start row")
    o = big.mean(axis=0)
    d = o - np.asarray(start[:2], dtype=float)
    d /= np.linalg.norm(d)
    n = np.array([-d[1], d[0]])
    lat, lon = (xy - o) @ n, (xy - o) @ d
    fits = {}
    for key, colour, sign in (("in_r", YELLOW, -1), ("out_r", BLUE, -1), ("in_l", BLUE, 1), ("out_l", YELLOW, 1)):
        pts = xy[(cls == colour) & (np.sign(lat) == sign)]
        if len(pts) < 3:
            raise InputError(f"{where}: skidpad circle {key} has {len(pts)} cones; at least 3 are needed")
        c, r, resid = fit_circle(pts)
        if resid > 0.3:
            raise InputError(f"{where}: the {CONE_NAMES[colour]} cones of skidpad circle {key} are not on a "
                             f"circle (RMS residual {resid:.2f} m)")
        fits[key] = (c, r)
    c_r = (fits["in_r"][0] + fits["out_r"][0]) / 2.0
    c_l = (fits["in_l"][0] + fits["out_l"][0]) / 2.0
    r_r, r_l = float(np.linalg.norm(c_r - o)), float(np.linalg.norm(c_l - o))
    lane = (cls == ORANGE) & (np.abs(lat) > 0.5)
    exit_len = float(lon[lane & (lon > 0)].max()) if (lane & (lon > 0)).any() else 2.0 * max(r_r, r_l)
    entry_len = float((o - np.asarray(start[:2])) @ d) + LEAD_M
    t = np.linspace(0.0, 4.0 * np.pi, int(4 * np.pi * max(r_r, r_l) / 0.05))
    a_r = np.arctan2(*(o - c_r)[::-1])
    a_l = np.arctan2(*(o - c_l)[::-1])
    pieces = [
        o + np.outer(np.linspace(-entry_len, 0.0, 200, endpoint=False), d),
        c_r + r_r * np.column_stack([np.cos(a_r - t), np.sin(a_r - t)])[:-1],
        c_l + r_l * np.column_stack([np.cos(a_l + t), np.sin(a_l + t)])[:-1],
        o + np.outer(np.linspace(0.0, exit_len, 200), d),
    ]
    line = resample(np.concatenate(pieces), closed=False)
    s, length = cumulative_length(line, closed=False)
    circle_len_r, circle_len_l = 4 * np.pi * r_r, 4 * np.pi * r_l
    seg = np.searchsorted([entry_len, entry_len + circle_len_r, entry_len + circle_len_r + circle_len_l], s)

    def lane_hw(sel: np.ndarray, sign: int) -> float:
        v = sign * lat[sel & (sign * lat > 0)]
        return float(np.median(v)) if len(v) else 1.5

    entry, exit_ = lane & (lon < 0), lane & (lon > 0)
    hwl = np.choose(seg, [lane_hw(entry, 1), fits["out_r"][1] - r_r, r_l - fits["in_l"][1], lane_hw(exit_, 1)])
    hwr = np.choose(seg, [lane_hw(entry, -1), r_r - fits["in_r"][1], fits["out_l"][1] - r_l, lane_hw(exit_, -1)])
    # the run ends with the rear axle 3 m short of the last cone row: the nose (2.15 m ahead of the
    # rear axle) stays clear of the cones that close the exit lane
    return dict(centerline=line, closed=False, event="skidpad", half_width_left=hwl.astype(float),
                half_width_right=hwr.astype(float), start_line_s=entry_len, finish_s=length - SKIDPAD_STOP_M,
                start_pose=_start_pose(line, False, start, entry_len, where))



def ring_layout(line: np.ndarray, width: float, spacing: float | None, min_radius: float,
                start_pair: float | None = None) -> dict:
    """Cones, widths and start of a generated closed track around ``line`` (s = 0 at line[0]).

    Blue cones at +width/2 (left), yellow at -width/2; the start line is marked on each side by one
    big orange cone, or with ``start_pair`` by two big orange cones ``start_pair`` metres apart along
    the track (as FS events and several EUFS layouts set it). Spacing: ``spacing`` metres, or 4.5 m on
    straights down to 3.5 m in the tightest corners (``min_radius``) when ``None``.
    """
    k = np.abs(curvatures(line, closed=True))
    target = (np.full(len(line), float(spacing)) if spacing is not None
              else 4.5 - 1.0 * np.clip(k * min_radius, 0.0, 1.0))
    sides = [place_on(offset(line, True, sign * width / 2.0), target, 0.0) for sign in (1.0, -1.0)]
    starts = [side[:1] for side in sides]
    if start_pair is not None:
        starts = []
        for side in sides:
            d = side[1] - side[0]
            d = d / np.linalg.norm(d) * (0.5 * float(start_pair))
            starts.append(np.stack([side[0] - d, side[0] + d]))
    cones = np.concatenate([starts[0], starts[1], sides[0][1:], sides[1][1:]])
    classes = np.concatenate([np.full(len(starts[0]) + len(starts[1]), BIG_ORANGE), np.full(len(sides[0]) - 1, BLUE),
                              np.full(len(sides[1]) - 1, YELLOW)]).astype(np.int64)
    hwl, hwr = half_widths(line, sides[0], sides[1], closed=True)
    length = polyline_length(line, closed=True)
    return dict(cones_xy=cones, cone_classes=classes, centerline=line, closed=True, event="trackdrive",
                half_width_left=hwl, half_width_right=hwr, start_line_s=0.0, finish_s=length,
                start_pose=_start_pose(line, True, None, 0.0, "generated"))
