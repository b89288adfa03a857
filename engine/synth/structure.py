"""Structural elements of one space: wall faces, floor, ceiling, doors, windows, columns, beams.

Walls are annotated as S3DIS does, per room: one ``wall`` instance per edge of
the space's clear footprint (a maximal straight run of wall face, possibly
across several physical walls), with holes where doors and windows are.  The
inside of a wall is never sampled: only its faces, each from its own space.

A door gives each space it joins its own ``door`` instance: the half of the
frame (jambs, head, casing) on that space's side, plus the leaf when the leaf
is in that space (an open leaf turned into the room) or closes the opening (a
closed leaf shows one face to each side).  A window belongs to the space
inside: reveals, frame, the glass (sampled sparsely, as glass returns few
points) and the sill board.
"""
from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon

from engine.synth import colours
from engine.synth.building import Element, Opening, Space, Wall
from engine.synth.geometry import Box, Poly, Rect, at, rect
from engine.synth.hard.elements import stair_elements, stair_slabs
from engine.synth.hard.hardness import HardContext

UP, DOWN = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
CASING_W, CASING_D = 0.07, 0.015
LEAF_T = 0.04
FRAME_W, FRAME_D = 0.05, 0.07
GLASS_INSET = 0.06  # glass plane distance from the outer face
GLASS_DENSITY = 0.06  # glazed partitions and glass doors return few points


def _v3(xy, z: float = 0.0) -> np.ndarray:
    return np.array([xy[0], xy[1], z], float)


def footprint_edges(space: Space) -> list[tuple[np.ndarray, np.ndarray]]:
    fp = space.footprint
    return [(fp[i], fp[(i + 1) % len(fp)]) for i in range(len(fp))]


def face_on_edge(space: Space, w: Wall, a: np.ndarray, e: np.ndarray) -> np.ndarray | None:
    """Start of ``w``'s face seen from ``space`` when that face lies on the footprint edge through ``a`` along ``e``."""
    d, n = w.direction, w.normal
    if abs(d[0] * e[1] - d[1] * e[0]) > 1e-6:
        return None
    face0 = np.asarray(w.p0) + n * w.side_of(space.id) * w.thickness / 2
    return None if abs(float(np.dot(a - face0, n))) > 1e-5 else face0


def edge_openings(space: Space, walls: list[Wall], a: np.ndarray, b: np.ndarray) -> list[tuple[float, float, Opening]]:
    """Openings on the footprint edge ``a -> b``: ``(s0, s1, opening)`` in metres from ``a``."""
    e = b - a
    length = float(np.hypot(*e))
    e = e / length
    out = []
    for wid in space.walls:
        w = walls[wid]
        if w.kind == "partial" or not w.openings:
            continue
        face0 = face_on_edge(space, w, a, e)
        if face0 is None:
            continue
        d = w.direction
        for o in w.openings:
            q0 = float(np.dot(face0 + d * o.s0 - a, e))
            q1 = float(np.dot(face0 + d * o.s1 - a, e))
            s0, s1 = max(min(q0, q1), 0.0), min(max(q0, q1), length)
            if s1 - s0 > 1e-6:
                out.append((s0, s1, o))
    return out


def add_structure(rng: np.random.Generator, space: Space, walls: list[Wall], openings: list[Opening],
                  style: dict, hard: HardContext | None = None) -> None:
    """Append the space's structural elements to ``space.elements``.

    ``hard`` (the building's difficulties) adds the grids of columns of open
    spaces (``open_plan``) and the stair of a stair tower (``stairs``); glazed
    partitions (``Wall.material == "glass"``) are drawn whenever a wall is one.
    """
    cols = space.colours
    z0, z1 = space.z0, space.z1
    # wall faces, one instance per footprint edge (the segments of a curved wall: one instance)
    faces = []
    for a, b in footprint_edges(space):
        e = b - a
        length = float(np.hypot(*e))
        inward = np.array([-e[1], e[0]]) / length
        holes = [(s0, s1, o.z0 - z0, min(o.z1, z1) - z0) for s0, s1, o in edge_openings(space, walls, a, b)]
        glass = glazed_parts(space, walls, a, b, holes)
        holes += [g["hole"] for g in glass]
        r = rect(_v3(a, z0), _v3(e), [0, 0, z1 - z0], _v3(inward), cols["wall"], holes=holes, jitter=5.0)
        faces.append(([r] + [p for g in glass for p in g["prims"]], math.atan2(e[1], e[0]), length))
    for group in _curve_groups(faces):
        prims = [p for i in group for p in faces[i][0]]
        yaw = faces[max(group, key=lambda i: faces[i][2])][1]
        space.elements.append(Element(-1, "wall", space.id, prims, yaw=yaw))
    # floor and ceiling (door thresholds join the floor below)
    floor_xy, ceiling_xy, ceiling_z = space.footprint.copy(), space.footprint.copy(), z1
    if space.stairs is not None:
        floor_xy, ceiling_xy, ceiling_z = stair_slabs(space)
    floor = Element(-1, "floor", space.id, [Poly(floor_xy, z0, True, cols["floor"],
                                                   jitter=cols.get("floor_jitter", 8.0))])
    ceiling = Element(-1, "ceiling", space.id, [Poly(ceiling_xy, ceiling_z, False, cols["ceiling"], jitter=4.0)])
    space.elements += [floor, ceiling]
    for wid in space.walls:
        w = walls[wid]
        if w.kind == "partial":
            space.elements.append(_partial_wall(w, cols))
            continue
        side = w.side_of(space.id)
        for o in w.openings:
            if o.kind == "door":
                el, threshold = _door_side(w, o, side, space, style)
                space.elements.append(el)
                floor.prims.append(threshold)
            else:
                space.elements.append(_window(w, o, side, space, style))
    _columns(rng, space, walls, style, hard)
    if space.stairs is not None:
        stair_elements(space)
    else:
        _beams(rng, space, walls, openings, style)
        _lights(rng, space, style)
    if _non_convex(space):  # an L-shaped room: its walls hide one arm from the other
        for wid in space.walls:
            w = walls[wid]
            if w.kind != "partial":
                body = w.body()
                c = body.mean(0)
                space.occluders.append(Box(np.array([c[0], c[1], (w.z0 + w.z1) / 2]),
                                           np.array([w.length + w.ext0 + w.ext1, w.thickness, w.z1 - w.z0]),
                                           w.yaw, (0, 0, 0)))


def _curve_groups(faces: list[tuple[list, float, float]], max_turn: float = 35.0) -> list[list[int]]:
    """Consecutive footprint edges turning by less than ``max_turn`` degrees (a curved wall): one group each."""
    n = len(faces)
    if n == 0:
        return []
    turn = [abs(math.remainder(faces[(i + 1) % n][1] - faces[i][1], 2 * math.pi)) for i in range(n)]
    smooth = [math.degrees(t) < max_turn for t in turn]  # edge i continues into edge i + 1
    groups: list[list[int]] = [[0]]
    for i in range(1, n):
        if smooth[i - 1]:
            groups[-1].append(i)
        else:
            groups.append([i])
    if len(groups) > 1 and smooth[n - 1]:
        groups[0] = groups.pop() + groups[0]
    return groups


def glazed_parts(space: Space, walls: list[Wall], a: np.ndarray, b: np.ndarray,
                 holes: list[tuple[float, float, float, float]]) -> list[dict]:
    """The glazed partitions along a footprint edge: their hole in the opaque face and their prims.

    A glass wall's face is sparse glass (6 % of the density) between the
    glazing heights, with its door openings left out; mullions every 1.0-1.5 m
    (the same for both faces: from the wall's own start), a bottom rail and a
    head rail at normal density, each half as deep as the wall (the half on
    this side).  Below and above the glazing the face stays solid.
    """
    e = b - a
    length = float(np.hypot(*e))
    if length < 1e-9:
        return []
    e = e / length
    inward = np.array([-e[1], e[0]])
    z0, z1 = space.z0, space.z1
    out = []
    for wid in space.walls:
        w = walls[wid]
        if w.material != "glass" or w.kind == "partial":
            continue
        face0 = face_on_edge(space, w, a, e)
        if face0 is None:
            continue
        d = w.direction
        q0, q1 = float(np.dot(face0 - a, e)), float(np.dot(face0 + d * w.length - a, e))
        s0, s1 = max(min(q0, q1), 0.0), min(max(q0, q1), length)
        if s1 - s0 < 0.05:
            continue
        g0, g1 = w.glazing
        g1 = min(g1, z1 - z0 - 0.02)
        if g1 - g0 < 0.3:
            continue
        glass_holes = [(max(h0, s0) - s0, min(h1, s1) - s0, t0 - g0, t1 - g0) for h0, h1, t0, t1 in holes
                       if h1 > s0 and h0 < s1]
        prims: list = [rect(_v3(a + e * s0, z0 + g0), _v3(e * (s1 - s0)), [0, 0, g1 - g0], _v3(inward),
                            colours.GLASS, holes=glass_holes, jitter=22.0, density=GLASS_DENSITY)]
        depth = w.thickness / 2
        frame = space.colours.get("door_frame", (180, 180, 180))
        yaw = math.atan2(e[1], e[0])
        pitch = 1.0 + 0.5 * ((wid * 0.6180339887) % 1.0)
        along = np.arange(pitch, w.length - 0.05, pitch)
        for t in along:  # positions along the wall -> along this edge
            s = float(np.dot(face0 + d * t - a, e))
            if not s0 + 0.03 < s < s1 - 0.03 or any(h0 - 0.03 < s < h1 + 0.03 for h0, h1, _, _ in holes):
                continue
            c = a + e * s - inward * depth / 2
            prims.append(Box(_v3(c, z0 + (g0 + g1) / 2), np.array([0.05, depth, g1 - g0]), yaw, frame, jitter=5.0))
        mid = a + e * (s0 + s1) / 2 - inward * depth / 2
        for zc in (g0 + 0.025, g1 - 0.025):
            prims.append(Box(_v3(mid, z0 + zc), np.array([s1 - s0, depth, 0.05]), yaw, frame, jitter=5.0))
        out.append({"hole": (s0, s1, g0, g1), "prims": prims})
    return out


def _non_convex(space: Space) -> bool:
    poly = Polygon(space.footprint)
    return poly.convex_hull.area - poly.area > 1e-3


def _partial_wall(w: Wall, cols: dict) -> Element:
    """A wall inside an open-plan space: a solid box from the wall it leans on to its free end."""
    d, _n = w.direction, w.normal
    s0, s1 = w.ext0, w.length - w.ext1
    mid = np.asarray(w.p0) + d * (s0 + s1) / 2
    b = Box(np.array([mid[0], mid[1], (w.z0 + w.z1) / 2]), np.array([s1 - s0, w.thickness, w.z1 - w.z0]),
            w.yaw, cols["wall"], jitter=5.0)
    return Element(-1, "wall", w.left, [b], yaw=w.yaw, info={"partial": True})


def _door_side(w: Wall, o: Opening, side: int, space: Space, style: dict) -> tuple[Element, Rect]:
    """The door instance of one side of a door opening, and the floor strip under the opening on that side."""
    d, n, p0 = w.direction, w.normal, w.p0
    t, zf, zh = w.thickness, w.z0, o.z1
    face = side * t / 2
    d3, n3 = _v3(d), _v3(n)
    frame_rgb = space.colours["door_frame"]
    leaf_rgb = space.colours["door"]
    leaf_kw = {}
    if w.material == "glass":  # glass doors in glazed partitions: sparse like the glass
        leaf_rgb, leaf_kw = colours.GLASS, {"jitter": 22.0, "density": GLASS_DENSITY}
    prims: list = [
        rect(at(p0, d, n, o.s0, 0, zf), n3 * face, [0, 0, zh - zf], d3, frame_rgb),
        rect(at(p0, d, n, o.s1, 0, zf), n3 * face, [0, 0, zh - zf], -d3, frame_rgb),
        rect(at(p0, d, n, o.s0, 0, zh), d3 * o.width, n3 * face, DOWN, frame_rgb),
    ]
    off = side * (t / 2 + CASING_D / 2)
    for s, size in ((o.s0 - CASING_W / 2, (CASING_W, CASING_D, zh - zf + CASING_W)),
                    (o.s1 + CASING_W / 2, (CASING_W, CASING_D, zh - zf + CASING_W))):
        c = at(p0, d, n, s, off, zf + size[2] / 2)
        prims.append(Box(c, np.array(size), w.yaw, frame_rgb))
    c = at(p0, d, n, (o.s0 + o.s1) / 2, off, zh + CASING_W / 2)
    prims.append(Box(c, np.array([o.width + 2 * CASING_W, CASING_D, CASING_W]), w.yaw, frame_rgb))
    if o.leaf != "none":
        lw = o.width / o.leaves - 0.01
        lh = zh - zf - 0.01
        hinges = [0] if o.leaves == 1 and o.id % 2 == 0 else [1] if o.leaves == 1 else [0, 1]
        for hinge in hinges:
            s_h = o.s0 + 0.005 if hinge == 0 else o.s1 - 0.005
            closed_dir = d if hinge == 0 else -d
            if o.leaf == "closed":
                off_leaf = o.swing * max(t / 2 - 0.01 - LEAF_T / 2, 0.0)
                c2 = np.asarray(p0) + d * s_h + closed_dir * lw / 2 + n * off_leaf
                prims.append(Box(_v3(c2, zf + lh / 2), np.array([lw, LEAF_T, lh]), w.yaw, leaf_rgb, **leaf_kw))
            elif o.swing == side:
                th = o.angle
                ldir = math.cos(th) * closed_dir + math.sin(th) * o.swing * n
                hinge_pt = np.asarray(p0) + d * s_h + n * o.swing * (t / 2 + 0.01)
                c2 = hinge_pt + ldir * lw / 2
                prims.append(Box(_v3(c2, zf + lh / 2), np.array([lw, LEAF_T, lh]),
                                 math.atan2(ldir[1], ldir[0]), leaf_rgb, **leaf_kw))
    threshold = rect(at(p0, d, n, o.s0, 0, zf), d3 * o.width, n3 * face, UP, space.colours["floor"],
                     jitter=space.colours.get("floor_jitter", 8.0))
    return Element(-1, "door", space.id, prims, yaw=w.yaw, info={"opening": o.id}), threshold


def _window(w: Wall, o: Opening, side: int, space: Space, style: dict) -> Element:
    """Reveals, frame, sparse glass and sill board of a window seen from inside."""
    d, n, p0 = w.direction, w.normal, w.p0
    t = w.thickness
    face = side * t / 2
    glass = -side * (t / 2 - GLASS_INSET)
    d3, n3 = _v3(d), _v3(n)
    reveal = space.colours["wall"]
    frame = style["window_frame"]
    zs, zh = o.z0, o.z1
    depth = n3 * (face - glass)
    prims: list = [
        rect(at(p0, d, n, o.s0, glass, zs), depth, [0, 0, zh - zs], d3, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s1, glass, zs), depth, [0, 0, zh - zs], -d3, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s0, glass, zs), d3 * o.width, depth, UP, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s0, glass, zh), d3 * o.width, depth, DOWN, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s0 + FRAME_W, glass, zs + FRAME_W), d3 * (o.width - 2 * FRAME_W),
             [0, 0, zh - zs - 2 * FRAME_W], n3 * side, colours.GLASS, jitter=22.0, density=0.15),
    ]
    space.mirrors.append(prims[-1])  # the pane: reflections are seen in it (hardness artefacts)
    fo = glass + side * FRAME_D / 2
    h = zh - zs
    bars = [(o.s0 + FRAME_W / 2, (zs + zh) / 2, FRAME_W, h), (o.s1 - FRAME_W / 2, (zs + zh) / 2, FRAME_W, h),
            ((o.s0 + o.s1) / 2, zs + FRAME_W / 2, o.width, FRAME_W), ((o.s0 + o.s1) / 2, zh - FRAME_W / 2, o.width, FRAME_W)]
    if o.width > 1.4:
        bars.append(((o.s0 + o.s1) / 2, (zs + zh) / 2, FRAME_W, h - 2 * FRAME_W))
    for s, z, bw, bh in bars:
        prims.append(Box(at(p0, d, n, s, fo, z), np.array([bw, FRAME_D, bh]), w.yaw, frame, jitter=5.0))
    sill = Box(at(p0, d, n, (o.s0 + o.s1) / 2, side * (t / 2 + 0.02), zs - 0.015),
               np.array([o.width + 0.1, 0.04, 0.03]), w.yaw, frame, jitter=5.0)
    prims.append(sill)
    return Element(-1, "window", space.id, prims, yaw=w.yaw, info={"opening": o.id})


def _columns(rng: np.random.Generator, space: Space, walls: list[Wall], style: dict,
             hard: HardContext | None = None) -> None:
    """Free-standing columns on a grid in big spaces; engaged columns (pilasters) along exterior walls.

    With ``open_plan`` every open space and lobby over 35 m^2 has its grid, of
    columns 0.4-0.8 m wide.
    """
    rgb = space.colours["column"]
    poly = Polygon(space.footprint)
    grid = hard is not None and hard.on("open_plan")
    if space.type in ("openspace", "lobby") and space.area > 35 and (
            rng.random() < (0.9 if space.type == "lobby" else 0.6) or grid):
        inner = poly.buffer(-1.3, join_style="mitre")
        lo, hi = space.footprint.min(0), space.footprint.max(0)
        step = style["grid"]
        nx, ny = max(1, int((hi[0] - lo[0]) // step)), max(1, int((hi[1] - lo[1]) // step))
        a = rng.uniform(0.3, 0.6)
        b = a if rng.random() < 0.7 else rng.uniform(0.3, 0.6)
        if grid:
            hr = hard.rng("open_plan", 1, space.id)
            a = hr.uniform(0.4, 0.8)
            b = a if hr.random() < 0.7 else hr.uniform(0.4, 0.8)
        for i in range(nx):
            for j in range(ny):
                x = lo[0] + (hi[0] - lo[0]) * (i + 1) / (nx + 1)
                y = lo[1] + (hi[1] - lo[1]) * (j + 1) / (ny + 1)
                if not inner.contains(Point(x, y)):
                    continue
                c = np.array([x, y, (space.z0 + space.z1) / 2])
                space.elements.append(Element(-1, "column", space.id,
                                              [Box(c, np.array([a, b, space.z1 - space.z0]), 0.0, rgb, jitter=5.0)]))
    if not style["pilasters"]:
        return
    for wid in space.walls:
        w = walls[wid]
        if w.kind != "exterior":
            continue
        side = w.side_of(space.id)
        busy = sorted((o.s0 - CASING_W - 0.05, o.s1 + CASING_W + 0.05) for o in w.openings)
        lo, hi = w.ext0 + 0.05, w.length - w.ext1 - 0.05
        gaps, x = [], lo
        for a, b in busy:
            if a > x:
                gaps.append((x, a))
            x = max(x, b)
        if hi > x:
            gaps.append((x, hi))
        width, depth = style["pilaster"]
        for a, b in gaps:
            if b - a < width + 0.3 or (a == lo and b == hi and b - a < 3 * width):
                continue
            s = (a + b) / 2
            # at most one per gap, and not in every gap
            if rng.random() < 0.6:
                c = at(w.p0, w.direction, w.normal, s, side * (w.thickness / 2 + depth / 2), (space.z0 + space.z1) / 2)
                space.elements.append(Element(-1, "column", space.id,
                                              [Box(c, np.array([width, depth, space.z1 - space.z0]), w.yaw, rgb,
                                                   jitter=5.0)], yaw=w.yaw, info={"engaged": True}))


def _beams(rng: np.random.Generator, space: Space, walls: list[Wall], openings: list[Opening], style: dict) -> None:
    """Beams under the ceiling across the space's shorter side, resting on its walls."""
    if not style["beams"] or rng.random() > (0.5 if space.type == "hallway" else 0.4):
        return
    door_top = max([o.z1 for wid in space.walls for o in walls[wid].openings] + [space.z0 + 2.0])
    room = space.z1 - door_top - 0.1
    if room < 0.2:
        return
    depth = min(rng.uniform(0.25, 0.5), room)
    width = rng.uniform(0.2, 0.4)
    poly = Polygon(space.footprint)
    lo, hi = space.footprint.min(0), space.footprint.max(0)
    ext = hi - lo
    along = int(np.argmin(ext))  # beams run along the short side
    across = 1 - along
    if space.type == "hallway":
        n = max(1, int(ext[across] // rng.uniform(4.0, 6.0)))
    else:
        n = int(rng.integers(1, 3))
    for k in range(n):
        pos = lo[across] + ext[across] * (k + 1) / (n + 1)
        if along == 0:
            line = LineString([(lo[0] - 1, pos), (hi[0] + 1, pos)])
        else:
            line = LineString([(pos, lo[1] - 1), (pos, hi[1] + 1)])
        piece = poly.intersection(line)
        segs = [g for g in getattr(piece, "geoms", [piece]) if g.geom_type == "LineString" and g.length > 0]
        if not segs:
            continue
        seg = max(segs, key=lambda g: g.length)
        (xa, ya), (xb, yb) = seg.coords[0], seg.coords[-1]
        size = [seg.length, width, depth] if along == 0 else [width, seg.length, depth]
        c = np.array([(xa + xb) / 2, (ya + yb) / 2, space.z1 - depth / 2])
        space.elements.append(Element(-1, "beam", space.id, [Box(c, np.array(size), 0.0, space.colours["beam"],
                                                                 jitter=5.0)]))


def _lights(rng: np.random.Generator, space: Space, style: dict) -> None:
    """Ceiling light panels (clutter) on a grid, clear of the walls and of beams."""
    if space.type == "storage" and rng.random() < 0.5:
        return
    poly = Polygon(space.footprint).buffer(-0.5, join_style="mitre")
    if poly.is_empty:
        return
    beams = [shapely.box(*(b.center[:2] - b.size[:2] / 2), *(b.center[:2] + b.size[:2] / 2))
             for e in space.elements if e.cls in ("beam", "column") for b in e.prims]
    lo, hi = space.footprint.min(0), space.footprint.max(0)
    step = style["light_step"]
    sx, sy = style["light_size"]
    xs = np.arange(lo[0] + step / 2, hi[0], step)
    ys = np.arange(lo[1] + step / 2, hi[1], step)
    for x in xs:
        for y in ys:
            cell = shapely.box(x - sx / 2 - 0.05, y - sy / 2 - 0.05, x + sx / 2 + 0.05, y + sy / 2 + 0.05)
            if not poly.contains(cell) or any(cell.intersects(b) for b in beams):
                continue
            c = np.array([x, y, space.z1 - 0.02])
            space.elements.append(Element(-1, "clutter", space.id,
                                          [Box(c, np.array([sx, sy, 0.04]), 0.0, colours.LIGHT, jitter=4.0)],
                                          info={"kind": "light"}))


def place_scanners(rng: np.random.Generator, space: Space, spacing: float = 5.0) -> None:
    """Scan positions about ``spacing`` apart in every cell of the space, clear of furniture, 1.35-1.65 m high."""
    poly = Polygon(space.footprint)
    inner = poly.buffer(-0.4, join_style="mitre")
    if inner.is_empty:
        inner = poly
    boxes = [b for e in space.elements for b in e.prims if isinstance(b, Box)
             and b.center[2] - b.size[2] / 2 < space.z0 + 1.9]
    blocked = None
    if boxes:
        feet = shapely.polygons(np.array([b.corners()[[0, 2, 6, 4], :2] for b in boxes]))
        blocked = shapely.union_all(shapely.buffer(feet, 0.3, quad_segs=2))
    free = inner.difference(blocked) if blocked is not None else inner
    if free.is_empty:
        free = inner
    shapely.prepare(free)
    pts = []
    for cell in space.cells:
        region = shapely.box(*cell).intersection(poly)
        if region.is_empty:
            continue
        lo = np.array(region.bounds[:2])
        hi = np.array(region.bounds[2:])
        n = np.maximum(1, np.ceil((hi - lo) / spacing)).astype(int)
        for i in range(n[0]):
            for j in range(n[1]):
                target = lo + (hi - lo) * (np.array([i, j]) + 0.5) / n
                pt = _free_point(rng, free, target, region)
                if pt is not None:
                    pts.append(pt)
    if not pts:
        p = inner.representative_point()
        pts.append((p.x, p.y))
    z = space.z0 + rng.uniform(1.35, 1.65, len(pts))
    space.scanners = np.c_[np.asarray(pts, float), z]


def _free_point(rng, free, target, region) -> tuple[float, float] | None:
    for r in (0.0, 0.4, 0.8, 1.2, 1.6, 2.0):
        for _ in range(1 if r == 0 else 8):
            p = target + (rng.uniform(-r, r, 2) if r else 0.0)
            if shapely.contains_xy(free, p[0], p[1]) and region.buffer(0.5).contains(Point(*p)):
                return float(p[0]), float(p[1])
    return None


def estimate_points(space: Space, density: float) -> float:
    """Upper bound of the points of a space (every surface fully seen) at ``density`` points per m^2."""
    total = 0.0
    for e in space.elements:
        for p in e.prims:
            if isinstance(p, Box):
                s = p.size
                total += 2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]) * p.density
            else:
                total += p.area * p.density
    return total * density * space.density
