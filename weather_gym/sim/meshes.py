"""Procedural meshes (Wavefront OBJ text) for the scene: traffic cones and textured ground quads.

PyBullet loads meshes from files, so the sim writes these strings to files named by their content
(:mod:`weather_gym.sim.mesh_files`).

Example:
    >>> from weather_gym.sim.meshes import cone_obj
    >>> text = cone_obj(height=0.325, base=0.228)
    >>> text.count("\\nf ") > 30
    True
"""

from __future__ import annotations

import math

CONE_TOP_RATIO = 0.12
"""Radius of the cone's flat top / radius of its bottom."""


def cone_dimensions(height: float, base: float, top_ratio: float = CONE_TOP_RATIO) -> dict[str, float]:
    """The cone mesh's measures (metres): ``plate_half`` (half side of the square base plate),
    ``plate_h`` (its thickness), ``r0``/``r1`` (frustum radius at the bottom / top), ``height``.
    The geometric ground truth (:mod:`weather_gym.sim.visibility`) projects the same solid."""
    r0 = 0.5 * base * 0.88  # frustum bottom radius (the square plate is a bit wider)
    return {"plate_half": 0.5 * base, "plate_h": 0.02 * height / 0.325, "r0": r0, "r1": r0 * top_ratio,
            "height": height}


def cone_obj(height: float, base: float, segments: int = 16, top_ratio: float = CONE_TOP_RATIO) -> str:
    """A Formula Student traffic cone: square base plate plus a textured frustum.

    The frustum's texture coordinate ``v`` runs from 0 at the bottom to 1 at the top, so a
    vertical texture strip paints the colour bands (body colour, stripe). The base plate uses
    ``v = 0.001`` (body colour at the bottom of the strip).
    """
    dims = cone_dimensions(height, base, top_ratio)
    r0, r1, plate_h = dims["r0"], dims["r1"], dims["plate_h"]
    lines = ["# weather-gym traffic cone"]
    verts: list[tuple[float, float, float]] = []
    uvs: list[tuple[float, float]] = []
    normals: list[tuple[float, float, float]] = []
    faces: list[str] = []

    # frustum side: ring at the bottom (z=plate_h) and top (z=height)
    slope = math.atan2(r0 - r1, height - plate_h)
    for i in range(segments + 1):
        a = 2 * math.pi * i / segments
        c, s = math.cos(a), math.sin(a)
        verts.append((r0 * c, r0 * s, plate_h))
        verts.append((r1 * c, r1 * s, height))
        uvs.append((i / segments, 0.0))
        uvs.append((i / segments, 1.0))
        n = (c * math.cos(slope), s * math.cos(slope), math.sin(slope))
        normals.extend([n, n])
    for i in range(segments):
        b0, t0, b1, t1 = 2 * i + 1, 2 * i + 2, 2 * i + 3, 2 * i + 4
        faces.append(f"f {b0}/{b0}/{b0} {b1}/{b1}/{b1} {t1}/{t1}/{t1}")
        faces.append(f"f {b0}/{b0}/{b0} {t1}/{t1}/{t1} {t0}/{t0}/{t0}")
    # top cap
    top_c = len(verts) + 1
    verts.append((0.0, 0.0, height))
    uvs.append((0.5, 1.0))
    normals.append((0.0, 0.0, 1.0))
    for i in range(segments):
        t0, t1 = 2 * i + 2, 2 * i + 4
        faces.append(f"f {t0}/{t0}/{top_c} {t1}/{t1}/{top_c} {top_c}/{top_c}/{top_c}")
    # square base plate (box of height plate_h), body colour
    h = dims["plate_half"]
    first = len(verts) + 1
    corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
    for z in (0.0, plate_h):
        for x, y in corners:
            verts.append((x, y, z))
            uvs.append((0.5, 0.001))
            normals.append((0.0, 0.0, 1.0 if z > 0 else -1.0))
    bot = [first + i for i in range(4)]
    top = [first + 4 + i for i in range(4)]
    faces.append(f"f {top[0]}/{top[0]}/{top[0]} {top[1]}/{top[1]}/{top[1]} {top[2]}/{top[2]}/{top[2]}")
    faces.append(f"f {top[0]}/{top[0]}/{top[0]} {top[2]}/{top[2]}/{top[2]} {top[3]}/{top[3]}/{top[3]}")
    for i in range(4):
        j = (i + 1) % 4
        faces.append(f"f {bot[i]}/{bot[i]}/{top[i]} {bot[j]}/{bot[j]}/{top[j]} {top[j]}/{top[j]}/{top[j]}")
        faces.append(f"f {bot[i]}/{bot[i]}/{top[i]} {top[j]}/{top[j]}/{top[j]} {top[i]}/{top[i]}/{top[i]}")

    lines += [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in verts]
    lines += [f"vt {u:.5f} {v:.5f}" for u, v in uvs]
    lines += [f"vn {x:.5f} {y:.5f} {z:.5f}" for x, y, z in normals]
    lines += faces
    return "\n".join(lines) + "\n"


def quad_obj(x0: float, y0: float, x1: float, y1: float, z: float = 0.0, uv_repeat: float = 1.0) -> str:
    """A horizontal rectangle facing up, texture coordinates spanning [0, uv_repeat]."""
    r = uv_repeat
    return (
        "# weather-gym ground quad\n"
        f"v {x0} {y0} {z}\nv {x1} {y0} {z}\nv {x1} {y1} {z}\nv {x0} {y1} {z}\n"
        f"vt 0 0\nvt {r} 0\nvt {r} {r}\nvt 0 {r}\n"
        "vn 0 0 1\n"
        "f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n"
    )


def box_obj(lx: float, ly: float, lz: float, z0: float = 0.0) -> str:
    """An axis-aligned box centred on x/y, from ``z0`` to ``z0 + lz`` (used for the car body)."""
    hx, hy = lx / 2, ly / 2
    v = [(-hx, -hy, z0), (hx, -hy, z0), (hx, hy, z0), (-hx, hy, z0)]
    v += [(x, y, z0 + lz) for x, y, _ in v]
    quads = [(0, 3, 2, 1, (0, 0, -1)), (4, 5, 6, 7, (0, 0, 1)), (0, 1, 5, 4, (0, -1, 0)),
             (1, 2, 6, 5, (1, 0, 0)), (2, 3, 7, 6, (0, 1, 0)), (3, 0, 4, 7, (-1, 0, 0))]
    lines = ["# box"] + [f"v {x} {y} {z}" for x, y, z in v] + ["vt 0.5 0.5"]
    for qi, (a, b, c, d, n) in enumerate(quads):
        lines.append(f"vn {n[0]} {n[1]} {n[2]}")
        k = qi + 1
        lines.append(f"f {a + 1}/1/{k} {b + 1}/1/{k} {c + 1}/1/{k}")
        lines.append(f"f {a + 1}/1/{k} {c + 1}/1/{k} {d + 1}/1/{k}")
    return "\n".join(lines) + "\n"
