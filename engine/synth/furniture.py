"""Furniture and clutter per room type: the recipes that furnish one space.

Each recipe draws pieces (:mod:`engine.synth.pieces`) and sets them down
with a :class:`engine.synth.placer.Placer`, which keeps them inside the clear
footprint, off each other (3-D boxes), out of door swings and clearances, and
keeps tall pieces away from windows.

Room types and what they hold (S3DIS room types): ``office`` (desks with
chairs, bookcases, a board), ``conferenceRoom`` (a long table ringed with
chairs, boards), ``hallway`` (a few pieces against the walls), ``lobby``
(sofas, low tables, plants, a reception desk), ``storage`` (shelves and
boxes), ``WC`` (toilets, stall partitions, sinks and mirrors: all clutter),
``openspace`` (clusters of desks).  Clutter (monitors, bins, plants, boxes,
pictures, radiators, lights) gets one instance per object, as in S3DIS.
"""
from __future__ import annotations

import math

import numpy as np
import shapely

from engine.synth import colours as C
from engine.synth.building import Opening, Space, Wall
from engine.synth.chairs import chair_shape, chair_stream, family_chair
from engine.synth.hard import furniture as hard_furniture
from engine.synth.pieces import bare_board, board, bookcase, chair, clutter, sofa, table
from engine.synth.placer import Placer


def furnish(rng: np.random.Generator, space: Space, walls: list[Wall], openings: list[Opening], style: dict,
            hard=None) -> None:
    """Put the furniture and clutter of the space's type into ``space.elements``.

    ``hard`` (a :class:`engine.synth.hard.hardness.HardContext`) adds the pieces of
    the difficulties (:mod:`engine.synth.hard.furniture`): tall cabinets on
    lined walls and hallway bottlenecks first, cubicles in open-plan offices,
    piles of boxes last.
    """
    p = Placer(rng, space, walls, style)
    p.hard = hard
    if hard is not None:
        hard_furniture.before(p, walls, hard)
    _radiators(p, walls)
    {"office": _office, "conferenceRoom": _conference, "hallway": _hallway, "lobby": _lobby,
     "storage": _storage, "WC": _wc, "openspace": _openspace, "stairs": _stairs}[space.type](p)
    _wall_clutter(p)
    if "furniture" in style:
        _name_chairs(space, style["furniture"])
    if hard is not None:
        hard_furniture.after(p, hard)


def _stairs(p: Placer) -> None:
    """A stair tower holds its stair (:mod:`engine.synth.hard.elements`), no furniture."""


def _desk_with_chair(p: Placer, *, free_xy=None, yaw=None, clutter_on=True) -> bool:
    rng = p.rng
    w, d, h = rng.uniform(1.2, 1.8), rng.uniform(0.6, 0.8), rng.uniform(0.72, 0.76)
    rgb = C.pick(rng, C.TABLES)
    if free_xy is None:
        el = p.against_wall("table", lambda: table(rng, w, d, h, rgb), w, d, h)
    else:
        el = p.put("table", table(rng, w, d, h, rgb), free_xy, yaw)
    if el is None:
        return False
    th = el.yaw
    front = np.array([math.sin(th), -math.cos(th)])
    centre = np.mean([b.center[:2] for b in el.prims[:1]], axis=0)
    if rng.random() < 0.9:
        cxy = centre + front * (d / 2 + rng.uniform(0.3, 0.5)) + rng.uniform(-0.3, 0.3) * np.array([math.cos(th), math.sin(th)])
        p.put("chair", _chair(p, C.pick(rng, C.CHAIRS)), cxy, th + math.pi + rng.uniform(-0.4, 0.4))
    if clutter_on:
        top = el.prims[0].center[2] + 0.015 - p.space.z0
        back = np.array([-math.sin(th), math.cos(th)])
        for kind, pr in (("monitor", 0.7), ("laptop", 0.3), ("papers", 0.5)):
            if rng.random() < pr:
                off = rng.uniform(-w / 2 + 0.35, w / 2 - 0.35)
                xy = centre + back * (d / 2 - 0.2 if kind == "monitor" else rng.uniform(-0.1, 0.1)) \
                    + off * np.array([math.cos(th), math.sin(th)])
                parts, _ = clutter(rng, kind, top)
                p.put("clutter", parts, xy, th + (rng.uniform(-0.2, 0.2) if kind != "monitor" else 0.0),
                      margin=0.002, info={"kind": kind})
        if rng.random() < 0.4:
            xy = centre + front * 0.1 + (w / 2 + 0.25) * np.array([math.cos(th), math.sin(th)])
            parts, _ = clutter(rng, "bin")
            p.put("clutter", parts, xy, th, info={"kind": "bin"})
    return True


def _chair(p: Placer, rgb: tuple) -> list:
    """A chair's parts: the classic chair, or in a ``furniture`` building one of the family's shapes
    (:mod:`engine.synth.chairs`) from the room's own furniture stream (the classic chair is drawn either way, so
    that the room's other draws stay the classic building's)."""
    parts = chair(p.rng, rgb)
    if "furniture" not in p.style:
        return parts
    k = sum(e.cls == "chair" for e in p.space.elements)  # this room's chairs placed so far
    return family_chair(chair_stream(p.style["furniture"], p.space.id, k), rgb)[0]


def _name_chairs(space: Space, furniture: int) -> None:
    """Record in each chair's ``info`` the family shape it was drawn with (the ``k``-th placed, the ``k``-th
    stream's first draw)."""
    chairs = [e for e in space.elements if e.cls == "chair"]
    for k, e in enumerate(chairs):
        e.info["shape"] = chair_shape(chair_stream(furniture, space.id, k))


def _bookcases(p: Placer, n: int, low_share: float = 0.3) -> None:
    rng = p.rng
    for _ in range(n):
        w, d = rng.uniform(0.8, 1.2), rng.uniform(0.3, 0.45)
        h = rng.uniform(0.75, 1.1) if rng.random() < low_share else rng.uniform(1.8, 2.2)
        h = min(h, p.space.z1 - p.space.z0 - 0.1)
        rgb = C.pick(rng, C.BOOKCASES)
        p.against_wall("bookcase", lambda: bookcase(rng, w, d, h, rgb), w, d, h, gap=0.0)


def _board(p: Placer, width=(1.2, 2.4), edge=None) -> None:
    rng = p.rng
    w, h = rng.uniform(*width), rng.uniform(0.9, 1.2)
    bottom = rng.uniform(0.85, 1.0)
    rgb = C.pick(rng, C.BOARDS)
    thickness = _bare_board(p)
    if thickness is None:
        info = {"style": "tray"} if "variety" in p.style else None  # (a classic building's records stay as they were)
        p.against_wall("board", lambda: board(rng, w, h, bottom, rgb), w, 0.1, h, bottom=bottom, gap=0.0, edge=edge,
                       info=info)
    else:
        p.against_wall("board", lambda: bare_board(w, h, bottom, rgb, thickness), w, thickness, h, bottom=bottom,
                       gap=0.0, edge=edge, info={"style": "bare", "thickness": round(thickness, 4)})


def _bare_board(p: Placer) -> float | None:
    """A board's style family in a ``varied`` building: None for the classic board with its pen tray (half of
    them), else the thickness of a bare board (1-4 cm), from the room's own variety stream; always None in a
    classic building (no draw at all: its other draws stay as they were)."""
    if "variety" not in p.style:
        return None
    k = sum(e.cls == "board" for e in p.space.elements)  # this room's boards placed so far
    r = np.random.default_rng([p.style["variety"], int(p.space.id), k])
    return float(r.uniform(0.01, 0.04)) if r.random() < 0.5 else None


def _floor_clutter(p: Placer, n: int, kinds=("box", "plant", "bin", "printer")) -> None:
    rng = p.rng
    for _ in range(n):
        kind = kinds[int(rng.integers(len(kinds)))]
        parts, (w, d) = clutter(rng, kind)
        if rng.random() < 0.7:
            p.against_wall("clutter", lambda: parts, w, d, 1.0, gap=0.05, info={"kind": kind})
        else:
            p.free_spot(10, lambda xy: p.put("clutter", parts, xy, rng.uniform(-math.pi, math.pi), info={"kind": kind}))


def _wall_clutter(p: Placer) -> None:
    """Pictures, clocks and fire extinguishers hung on walls."""
    rng = p.rng
    n = int(rng.integers(0, 3)) if p.space.type != "WC" else 0
    for _ in range(n):
        kind = rng.choice(["picture", "clock", "extinguisher"], p=[0.6, 0.2, 0.2])
        if kind == "picture":
            w, d, h, z = rng.uniform(0.4, 1.0), 0.03, rng.uniform(0.3, 0.8), rng.uniform(1.3, 1.6)
        elif kind == "clock":
            w, d, h, z = 0.3, 0.05, 0.3, rng.uniform(2.0, 2.2)
        else:
            w, d, h, z = 0.2, 0.16, 0.55, 0.15
        z = min(z, p.space.z1 - p.space.z0 - h - 0.1)
        rgb = C.vivid(rng)
        p.against_wall("clutter", lambda: [(0, 0, z + h / 2, w, d, h, rgb)],
                       w, d, h, bottom=z, gap=0.0, info={"kind": str(kind)})


def _radiators(p: Placer, walls: list[Wall]) -> None:
    """Radiators (clutter) under most windows."""
    for _i, ed in enumerate(p.edges):
        for s0, s1, o in ed["openings"]:
            if o.kind != "window" or p.rng.random() < 0.3:
                continue
            w = min(s1 - s0 - 0.1, p.rng.uniform(0.8, 1.6))
            h = min(0.6, o.z0 - p.space.z0 - 0.2)
            if w < 0.4 or h < 0.3:
                continue
            xy = ed["a"] + ed["e"] * (s0 + s1) / 2 + ed["n"] * 0.08
            yaw = math.atan2(ed["n"][0], -ed["n"][1])
            p.put("clutter", [(0, 0, 0.12 + h / 2, w, 0.1, h, (225, 225, 222))], xy, yaw, margin=0.0,
                  info={"kind": "radiator"})


def _office(p: Placer) -> None:
    rng, area = p.rng, p.space.area
    for _ in range(int(np.clip(round(area / 9), 1, 4))):
        _desk_with_chair(p)
    _bookcases(p, int(rng.choice([0, 1, 2], p=[0.3, 0.4, 0.3])))
    if rng.random() < 0.4:
        _board(p)
    if area > 15 and rng.random() < 0.15:
        p.against_wall("sofa", lambda: sofa(rng, 1.8, C.pick(rng, C.SOFAS)), 1.8, 0.95, 0.9)
    _floor_clutter(p, int(rng.integers(0, 4)))


def _inner_rect(p: Placer) -> tuple[np.ndarray, np.ndarray]:
    """The biggest cell of the space clipped to its footprint (for central furniture)."""
    best = None
    for cell in p.space.cells:
        r = shapely.box(*cell).intersection(p.poly)
        if not r.is_empty and (best is None or r.area > best.area):
            best = r
    b = np.array(best.bounds)
    return b[:2], b[2:]


def _conference(p: Placer) -> None:
    rng = p.rng
    lo, hi = _inner_rect(p)
    ext = hi - lo
    long_ax = int(np.argmax(ext))
    L = float(np.clip(0.55 * ext[long_ax], 1.6, 5.0))
    W = float(min(rng.uniform(1.0, 1.4), max(0.8, ext[1 - long_ax] - 2.0)))
    yaw = 0.0 if long_ax == 0 else math.pi / 2
    rgb = C.pick(rng, C.TABLES)
    el = None
    for attempt in range(16):  # shorter and off-centre when doors or columns are in the way
        size = np.array([L, W]) if long_ax == 0 else np.array([W, L])
        slack = np.maximum((ext - size) / 2 - 0.7, 0.0)
        centre = (lo + hi) / 2 + rng.uniform(-1, 1, 2) * slack * min(1.0, attempt / 4)
        el = p.put("table", table(rng, L, W, 0.74, rgb), centre, yaw)
        if el is not None:
            break
        L = max(1.6, L * 0.92)
    if el is not None:
        ax = np.array([math.cos(yaw), math.sin(yaw)])
        side = np.array([-math.sin(yaw), math.cos(yaw)])
        rgb = C.pick(rng, C.CHAIRS)
        n = max(1, int(L // 0.75))
        for k in range(n):
            off = (k + 0.5) * L / n - L / 2
            for sgn in (-1, 1):
                if rng.random() < 0.85:
                    xy = centre + ax * off + side * sgn * (W / 2 + rng.uniform(0.3, 0.45))
                    face = yaw + (0 if sgn > 0 else math.pi)  # back away from the table
                    p.put("chair", _chair(p, rgb), xy, face + rng.uniform(-0.3, 0.3))
        for sgn in (-1, 1):
            if rng.random() < 0.5:
                xy = centre + ax * sgn * (L / 2 + 0.4)
                p.put("chair", _chair(p, rgb), xy, yaw + (-math.pi / 2 if sgn > 0 else math.pi / 2))
        for _ in range(int(rng.integers(0, 4))):
            kind = str(rng.choice(["laptop", "papers"]))
            parts, _ = clutter(rng, kind, 0.74)
            xy = centre + ax * rng.uniform(-L / 2 + 0.3, L / 2 - 0.3) + side * rng.uniform(-W / 2 + 0.2, W / 2 - 0.2)
            p.put("clutter", parts, xy, yaw + rng.uniform(-0.5, 0.5), margin=0.002, info={"kind": kind})
    _board(p, (1.8, 3.6))
    if rng.random() < 0.3:
        _board(p)
    if rng.random() < 0.3:
        _bookcases(p, 1, low_share=0.6)
    if rng.random() < 0.2:
        p.against_wall("sofa", lambda: sofa(rng, 2.0, C.pick(rng, C.SOFAS)), 2.0, 0.95, 0.9)
    _floor_clutter(p, int(rng.integers(0, 3)), kinds=("plant", "bin", "box"))


def _hallway(p: Placer) -> None:
    rng = p.rng
    lo, hi = p.space.footprint.min(0), p.space.footprint.max(0)
    width = float(min(hi - lo))
    length = float(max(hi - lo))
    for _ in range(int(length // 6)):
        r = rng.random()
        if r < 0.25 and width >= 2.1:
            w, d, h = rng.uniform(0.8, 1.2), rng.uniform(0.3, 0.4), rng.uniform(0.9, 2.0)
            rgb = C.pick(rng, C.BOOKCASES)
            p.against_wall("bookcase", lambda: bookcase(rng, w, d, h, rgb), w, d, h, gap=0.0)
        elif r < 0.55:
            _board(p, (0.8, 1.6))
        elif r < 0.85:
            _floor_clutter(p, 1, kinds=("bin", "plant", "cooler"))
        elif r < 0.92 and width >= 2.4:
            p.against_wall("sofa", lambda: sofa(rng, 1.6, C.pick(rng, C.SOFAS)), 1.6, 0.95, 0.9)
        elif width >= 2.2:
            p.against_wall("chair", lambda: _chair(p, C.pick(rng, C.CHAIRS)), 0.56, 0.56, 1.0, gap=0.05)


def _lobby(p: Placer) -> None:
    rng = p.rng
    for _ in range(int(rng.integers(1, 4))):
        w = rng.uniform(1.6, 2.4)
        el = p.against_wall("sofa", lambda: sofa(rng, w, C.pick(rng, C.SOFAS)), w, 0.95, 0.9)
        if el is not None and rng.random() < 0.7:
            th = el.yaw
            front = np.array([math.sin(th), -math.cos(th)])
            c = np.mean([b.center[:2] for b in el.prims], axis=0) + front * 1.05
            tw = min(w - 0.4, 1.2)
            p.put("table", table(rng, tw, 0.6, 0.45, C.pick(rng, C.TABLES)), c, th)
    if rng.random() < 0.5:
        _desk_with_chair(p)
    for _ in range(int(rng.integers(2, 5))):
        p.free_spot(10, lambda xy: p.put("chair", _chair(p, C.pick(rng, C.CHAIRS)), xy, rng.uniform(-math.pi, math.pi)))
    _floor_clutter(p, int(rng.integers(2, 5)), kinds=("plant", "plant", "bin"))
    if rng.random() < 0.5:
        _board(p)
    if rng.random() < 0.3:
        _bookcases(p, 1)


def _storage(p: Placer) -> None:
    rng = p.rng
    _bookcases(p, int(rng.integers(2, 7)), low_share=0.15)
    if rng.random() < 0.2:
        _desk_with_chair(p, clutter_on=False)
    _floor_clutter(p, int(rng.integers(4, 12)), kinds=("box", "box", "box", "bin", "printer"))


def _wc(p: Placer) -> None:
    """Stalls (toilets between partitions) along the longest wall, sinks with mirrors on another."""
    rng = p.rng
    order = sorted(range(len(p.edges)), key=lambda i: -p.edges[i]["len"])
    if not order:
        return
    ed = p.edges[order[0]]
    n = int(min(3, (ed["len"] - 0.2) // 0.95))
    start = (ed["len"] - n * 0.95) / 2
    yaw = math.atan2(ed["n"][0], -ed["n"][1])
    grey = C.pick(rng, [(200, 200, 195), (150, 160, 170), (120, 100, 90)])
    proj = p.space.footprint @ ed["n"]
    depth = float(min(1.4, proj.max() - proj.min() - 0.9))
    if depth < 0.8:
        n = 0
    for k in range(n):
        s = start + (k + 0.5) * 0.95
        xy = ed["a"] + ed["e"] * s + ed["n"] * 0.38
        parts, _ = clutter(rng, "toilet")
        p.put("clutter", parts, xy, yaw, info={"kind": "toilet"})
    for k in range(n + 1 if n else 0):
        s = start + k * 0.95
        xy = ed["a"] + ed["e"] * s + ed["n"] * (depth / 2 + 0.01)
        p.put("clutter", [(0, 0, 0.15 + 0.95, 0.03, depth, 1.9, grey)], xy, yaw, margin=0.0,
              info={"kind": "partition"})
    for i in order[1:3]:
        for _ in range(int(rng.integers(1, 3))):
            el = p.against_wall("clutter", lambda: [(0, 0, 0.8, 0.5, 0.42, 0.16, (235, 235, 235))], 0.5, 0.42, 0.9,
                                bottom=0.7, gap=0.0, edge=i, info={"kind": "sink"})
            if el is not None:
                th = el.yaw
                back = np.array([-math.sin(th), math.cos(th)])
                c = el.prims[0].center[:2] + back * (0.21 - 0.015)
                p.put("clutter", [(0, 0, 1.55, 0.6, 0.02, 0.8, (190, 200, 205))], c, th, margin=0.0,
                      info={"kind": "mirror"})
    _floor_clutter(p, 1, kinds=("bin",))


def _openspace(p: Placer) -> None:
    """Clusters of two desks back to back with chairs, on a loose grid, plus shelves and boards."""
    rng = p.rng
    lo, hi = p.space.footprint.min(0), p.space.footprint.max(0)
    yaw = 0.0 if rng.random() < 0.5 else math.pi / 2
    step = np.array([rng.uniform(2.6, 3.2), rng.uniform(3.0, 3.6)])
    if yaw:
        step = step[::-1]
    xs = np.arange(lo[0] + 1.6, hi[0] - 1.2, step[0])
    ys = np.arange(lo[1] + 1.8, hi[1] - 1.2, step[1])
    pods = p.hard is not None and p.hard.on("open_plan")
    for x in xs:
        for y in ys:
            w, d = rng.uniform(1.2, 1.6), rng.uniform(0.7, 0.8)
            ax = np.array([-math.sin(yaw), math.cos(yaw)])
            if pods:  # a cubicle pod: low partitions between and beside the two desks
                hard_furniture.cubicle(p, np.array([x, y]), yaw, w, d)
            for sgn in (1, -1):
                xy = np.array([x, y]) + ax * sgn * (d / 2 + (0.04 if pods else 0.01))
                _desk_with_chair(p, free_xy=xy, yaw=yaw + (0 if sgn < 0 else math.pi))
    _bookcases(p, int(rng.integers(1, 4)))
    for _ in range(int(rng.integers(1, 3))):
        _board(p)
    _floor_clutter(p, int(rng.integers(2, 5)), kinds=("plant", "bin", "printer", "box"))
    if rng.random() < 0.3:
        p.against_wall("sofa", lambda: sofa(rng, 2.0, C.pick(rng, C.SOFAS)), 2.0, 0.95, 0.9)
