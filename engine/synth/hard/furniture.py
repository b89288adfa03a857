"""Furniture of the difficulties (:mod:`engine.synth.hard.hardness`): lined walls, bottlenecks, cubicles, piles of boxes.

Placed by the same :class:`engine.synth.placer.Placer` as the ordinary
furniture (inside the footprint, off each other, out of doorways), in the
space's own frame, but with the difficulty's own random stream (the placer's
stream is swapped for the duration) so that the ordinary pieces draw the same
numbers as in a clean building.

* ``hidden_walls``: along the faces listed in ``Wall.lined``, a run of closed
  cabinets (class bookcase) 0.45-0.6 m deep, 2.0-2.4 m tall or up to 3 cm
  under the ceiling, over 60-95 % of the face;
* ``bottlenecks``, in hallways, one per 8 m or so: a free-standing column
  leaving a passage of 1.1 m or more; a pair of piers (engaged columns)
  narrowing the hallway to 1.0-1.4 m, with a soffit across (a beam: a
  *portal*) one time in three; or a run of tall lockers (bookcase);
* ``open_plan``: cubicles (:func:`cubicle`): a spine panel between two desks
  back to back and a panel at each end, 1.1-1.7 m tall (clutter, ``kind:
  "partition"``): they do not reach the ceiling, so they do not divide the space;
* ``clutter``: piles of two to five boxes, 1.0-2.2 m tall (clutter, ``kind:
  "boxes"``), about one per 7 m^2 of rooms, fewer in hallways, most against walls.
"""
from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

from engine.synth import colours as C
from engine.synth.building import Wall
from engine.synth.hard.hardness import HardContext
from engine.synth.placer import Placer


@contextmanager
def _stream(p: Placer, rng: np.random.Generator):
    old, p.rng = p.rng, rng
    try:
        yield rng
    finally:
        p.rng = old


def before(p: Placer, walls: list[Wall], hard: HardContext) -> None:
    """Pieces that claim their place before the ordinary furniture."""
    sp = p.space
    if hard.on("hidden_walls"):
        with _stream(p, hard.rng("hidden_walls", 100, sp.id)) as rng:
            line_faces(p, walls, rng)
    if hard.on("bottlenecks") and sp.type == "hallway":
        with _stream(p, hard.rng("bottlenecks", 100, sp.id)) as rng:
            bottlenecks(p, rng, hard.level("bottlenecks"))


def after(p: Placer, hard: HardContext) -> None:
    """Pieces that fill what the ordinary furniture left."""
    if hard.on("clutter") and p.space.type != "stairs":
        with _stream(p, hard.rng("clutter", 100, p.space.id)) as rng:
            piles(p, rng, hard.level("clutter"))


# -- hidden walls ---------------------------------------------------------------------------------
def _face_interval(p: Placer, w: Wall, ed: dict) -> tuple[float, float] | None:
    """The stretch ``(s0, s1)`` of a footprint edge that lies on a wall's face on this space's side."""
    e, a = ed["e"], ed["a"]
    d, n = w.direction, w.normal
    if abs(d[0] * e[1] - d[1] * e[0]) > 1e-6:
        return None
    face0 = np.asarray(w.p0) + n * w.side_of(p.space.id) * w.thickness / 2
    if abs(float(np.dot(a - face0, n))) > 1e-5:
        return None
    q0, q1 = float(np.dot(face0 - a, e)), float(np.dot(face0 + d * w.length - a, e))
    s0, s1 = max(min(q0, q1), 0.0), min(max(q0, q1), ed["len"])
    return (s0, s1) if s1 - s0 > 0.5 else None


def line_faces(p: Placer, walls: list[Wall], rng: np.random.Generator) -> None:
    """Closed tall cabinets along the faces of the walls that list this space in ``lined``."""
    sp = p.space
    room = sp.z1 - sp.z0
    for wid in sp.walls:
        w = walls[wid]
        if sp.id not in w.lined:
            continue
        for ed in p.edges:
            iv = _face_interval(p, w, ed)
            if iv is None:
                continue
            s0, s1 = iv
            cover = rng.uniform(0.6, 0.95) * (s1 - s0)
            h = room - 0.03 if rng.random() < 0.3 else min(rng.uniform(2.0, 2.4), room - 0.05)
            depth = rng.uniform(0.45, 0.6)
            rgb = C.pick(rng, C.BOOKCASES)
            s = s0 + rng.uniform(0.0, max(s1 - s0 - cover, 0.0))
            placed, tries = 0.0, 0
            while placed < cover and s < s1 - 0.4 and tries < 60:
                tries += 1
                width = min(rng.uniform(0.8, 1.2), s1 - s - 0.01)
                if width < 0.4:
                    break
                n = ed["n"]
                xy = ed["a"] + ed["e"] * (s + width / 2) + n * (0.01 + depth / 2)
                yaw = math.atan2(n[0], -n[1])
                parts = [(0, 0, h / 2, width, depth, h, rgb)]
                if p.put("bookcase", parts, xy, yaw, margin=0.003, info={"kind": "cabinet"}) is not None:
                    placed += width
                    s += width + 0.005
                else:
                    s += 0.3


# -- hallway bottlenecks ----------------------------------------------------------------------------
def bottlenecks(p: Placer, rng: np.random.Generator, level: float) -> None:
    """Columns, piers, portals and lockers along a hallway (in its own frame: axis-aligned)."""
    sp = p.space
    lo, hi = sp.footprint.min(0), sp.footprint.max(0)
    ext = hi - lo
    along = int(np.argmax(ext))
    across = 1 - along
    width, length = float(ext[across]), float(ext[along])
    n = int(round(length / 8.0 * level + rng.uniform(0.0, 0.6)))
    if length >= 6 and n == 0 and level >= 1:
        n = 1
    room = sp.z1 - sp.z0
    rgb = sp.colours.get("column", (200, 200, 195))

    def at(u: float, v: float) -> np.ndarray:
        xy = np.zeros(2)
        xy[along], xy[across] = u, v
        return xy

    def size(du: float, dv: float) -> tuple[float, float]:
        return (du, dv) if along == 0 else (dv, du)

    for _ in range(n):
        for _try in range(8):
            u = float(rng.uniform(lo[along] + 1.0, hi[along] - 1.0))
            kind = rng.choice(["column", "piers", "portal", "lockers"], p=[0.3, 0.3, 0.15, 0.25])
            if kind == "column" and width >= 1.7:
                c = rng.uniform(0.3, 0.5)
                gap = rng.uniform(0.25, 0.45)
                if width - gap - c < 1.1:
                    continue
                v = lo[across] + gap + c / 2 if rng.random() < 0.5 else hi[across] - gap - c / 2
                sx, sy = size(c, c)
                if p.put("column", [(0, 0, room / 2, sx, sy, room, rgb)], at(u, v), 0.0, margin=0.0) is not None:
                    break
            elif kind in ("piers", "portal"):
                passage = rng.uniform(1.0, 1.4)
                depth = (width - passage) / 2
                if depth < 0.2:
                    continue
                length_p = rng.uniform(0.4, 1.2)
                sx, sy = size(length_p, depth)
                pier = [(0, 0, room / 2, sx, sy, room, rgb)]
                spots = [at(u, lo[across] + depth / 2), at(u, hi[across] - depth / 2)]
                if not all(p.fits(p.build(pier, xy, 0.0), 0.0) for xy in spots):
                    continue
                for xy in spots:
                    p.put("column", pier, xy, 0.0, margin=0.0, info={"engaged": True})
                if kind == "portal":
                    drop = min(rng.uniform(0.4, 0.7), room - 2.1)
                    if drop > 0.1:
                        bx, by = size(length_p, passage)
                        middle = at(u, (lo[across] + hi[across]) / 2)
                        p.put("beam", [(0, 0, room - drop / 2, bx, by, drop, rgb)], middle, 0.0, z=sp.z0, margin=0.0)
                break
            elif kind == "lockers":
                depth = rng.uniform(0.45, 0.55)
                if width - depth < 1.1:
                    continue
                run = min(rng.uniform(1.5, 4.0), length - 2.0)
                h = rng.uniform(1.8, 2.1)
                sx, sy = size(run, depth)
                v = lo[across] + depth / 2 + 0.01 if rng.random() < 0.5 else hi[across] - depth / 2 - 0.01
                if p.put("bookcase", [(0, 0, h / 2, sx, sy, h, C.pick(rng, C.BOOKCASES))], at(u, v), 0.0,
                         margin=0.0, info={"kind": "lockers"}) is not None:
                    break


# -- cubicles -----------------------------------------------------------------------------------------
def cubicle(p: Placer, centre: np.ndarray, yaw: float, w: float, d: float) -> None:
    """Low partitions of a pod of two desks back to back: a spine between them and a panel at each end."""
    rng = p.hard.rng("open_plan", 200, p.space.id, int(abs(centre[0]) * 100), int(abs(centre[1]) * 100))
    h = rng.uniform(1.1, 1.7)
    grey = C.pick(rng, [(150, 155, 160), (120, 125, 135), (170, 160, 140)])
    t = 0.05
    half = 0.9 + 0.08  # clear of the widest desk (1.8 m)
    parts = [(0, 0, h / 2, 2 * half - 0.06, t, h, grey)]
    for sx in (-1, 1):
        parts.append((sx * half, 0, h / 2, t, 2 * d + 0.1, h, grey))
    for part in parts:
        p.put("clutter", [part], centre, yaw, margin=0.0, info={"kind": "partition"})


# -- heavy clutter -------------------------------------------------------------------------------------
def pile(rng: np.random.Generator) -> tuple[list, tuple[float, float]]:
    """A pile of two to five boxes, each a little smaller and shifted on the one below (1.0-2.2 m)."""
    w, d = rng.uniform(0.45, 0.8), rng.uniform(0.35, 0.6)
    target = rng.uniform(1.0, 2.2)
    parts, z = [], 0.0
    bw, bd = w, d
    while z < target and len(parts) < 5:
        h = rng.uniform(0.3, 0.55)
        ox, oy = rng.uniform(-0.04, 0.04, 2)
        parts.append((ox, oy, z + h / 2, bw, bd, h, C.pick(rng, [(170, 130, 85), (190, 150, 100), (150, 120, 90)])))
        z += h
        bw, bd = bw * rng.uniform(0.85, 1.0), bd * rng.uniform(0.85, 1.0)
    return parts, (w + 0.08, d + 0.08)


def piles(p: Placer, rng: np.random.Generator, level: float) -> None:
    """Piles of boxes: about one per 7 m^2 of a room (one per 10 m of hallway), 70 % against walls."""
    sp = p.space
    if sp.type in ("hallway", "lobby"):
        n = int(max(sp.footprint.max(0) - sp.footprint.min(0)) / 10.0 * level)
    else:
        n = int(round(sp.area / 7.0 * level))
    for _ in range(min(n, 20)):
        parts, (w, d) = pile(rng)
        if rng.random() < 0.7:
            p.against_wall("clutter", lambda: parts, w, d, 2.2, gap=0.03, info={"kind": "boxes"}, tries=6)
        else:
            p.free_spot(8, lambda xy: p.put("clutter", parts, xy, rng.uniform(-math.pi, math.pi),
                                            info={"kind": "boxes"}))
