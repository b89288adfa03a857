"""Structural elements of one space: wall faces, floor, ceiling, doors, windows, columns, beams, lights.

:func:`add_structure` puts them in order: the wall faces
(:mod:`engine.synth.faces`), floor and ceiling, partial walls, the door and
window elements (:mod:`engine.synth.frames`), then columns, beams and light
panels (here), and the stair of a stair tower (:mod:`engine.synth.hard.elements`).
"""
from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon

from engine.synth import colours
from engine.synth.building import Element, Opening, Space, Wall
from engine.synth.faces import add_wall_faces, partial_wall
from engine.synth.frames import CASING_W, door_side, window
from engine.synth.geometry import Box, Poly, at
from engine.synth.hard.elements import stair_elements, stair_slabs
from engine.synth.hard.hardness import HardContext


def add_structure(rng: np.random.Generator, space: Space, walls: list[Wall], openings: list[Opening],
                  style: dict, hard: HardContext | None = None) -> None:
    """Append the space's structural elements to ``space.elements``.

    ``hard`` (the building's difficulties) adds the grids of columns of open
    spaces (``open_plan``) and the stair of a stair tower (``stairs``); glazed
    partitions (``Wall.material == "glass"``) are drawn whenever a wall is one.
    """
    cols = space.colours
    z0, z1 = space.z0, space.z1
    add_wall_faces(space, walls)
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
            space.elements.append(partial_wall(w, cols))
            continue
        side = w.side_of(space.id)
        for o in w.openings:
            if o.kind == "door":
                el, threshold = door_side(w, o, side, space, style)
                space.elements.append(el)
                floor.prims.append(threshold)
            else:
                space.elements.append(window(w, o, side, space, style))
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


def _non_convex(space: Space) -> bool:
    poly = Polygon(space.footprint)
    return poly.convex_hull.area - poly.area > 1e-3


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
