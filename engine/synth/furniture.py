"""Furniture and clutter: realistic pieces made of boxes, placed per room type.

A piece is a list of part boxes in its own frame (origin at the centre of its
footprint on the floor, x across, y towards its back, z up), turned by a yaw and
set down in the space.  Tables have a top and legs (the floor shows between
them), chairs a seat, a back and a base, bookcases sides, shelves and books,
sofas a base that hides the floor, boards hang on walls.  Placement keeps
pieces inside the clear footprint, off each other (3-D boxes), out of door
swings and clearances, and keeps tall pieces away from windows.

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
from shapely.geometry import Polygon

from engine.synth import colours as C
from engine.synth.building import Element, Opening, Space, Wall
from engine.synth.geometry import Box
from engine.synth.structure import edge_openings, footprint_edges

Part = tuple[float, float, float, float, float, float, tuple]  # cx, cy, cz, sx, sy, sz, rgb


# -- pieces (local frames) -----------------------------------------------------------------
def table(rng: np.random.Generator, w: float, d: float, h: float, rgb: tuple) -> list[Part]:
    """A table or desk ``w`` x ``d``, top at ``h``: a top on four legs, or on side panels with a modesty panel."""
    top = 0.03
    parts: list[Part] = [(0, 0, h - top / 2, w, d, top, rgb)]
    if rng.random() < 0.6:
        leg = C.METAL if rng.random() < 0.5 else rgb
        for sx in (-1, 1):
            for sy in (-1, 1):
                parts.append((sx * (w / 2 - 0.05), sy * (d / 2 - 0.05), (h - top) / 2, 0.05, 0.05, h - top, leg))
    else:  # desk with side panels and a modesty panel
        for sx in (-1, 1):
            parts.append((sx * (w / 2 - 0.015), 0, (h - top) / 2, 0.03, d, h - top, rgb))
        parts.append((0, d / 2 - 0.06, h - top - 0.25, w - 0.06, 0.02, 0.35, rgb))
    return parts


def chair(rng: np.random.Generator, rgb: tuple) -> list[Part]:
    """An office chair (post and star base, maybe armrests) or a four-legged chair; back towards +y."""
    seat_z = rng.uniform(0.42, 0.5)
    parts: list[Part] = [(0, 0, seat_z, 0.46, 0.46, 0.07, rgb),
                         (0, 0.2, seat_z + 0.04 + 0.23, 0.44, 0.06, 0.46, rgb)]
    if rng.random() < 0.6:  # office chair: post and star base
        parts += [(0, 0, (0.07 + seat_z - 0.035) / 2, 0.05, 0.05, seat_z - 0.035 - 0.07, C.METAL),
                  (0, 0, 0.035, 0.56, 0.05, 0.07, C.METAL), (0, 0, 0.035, 0.05, 0.56, 0.07, C.METAL)]
        if rng.random() < 0.5:
            for sx in (-1, 1):
                parts.append((sx * 0.25, -0.02, seat_z + 0.22, 0.05, 0.3, 0.03, C.METAL))
                parts.append((sx * 0.25, 0.05, seat_z + 0.1, 0.03, 0.03, 0.2, C.METAL))
    else:  # four legs
        lz = seat_z - 0.035
        for sx in (-1, 1):
            for sy in (-1, 1):
                parts.append((sx * 0.2, sy * 0.2, lz / 2, 0.03, 0.03, lz, C.METAL))
    return parts


def sofa(rng: np.random.Generator, w: float, rgb: tuple) -> list[Part]:
    """A sofa ``w`` wide: a base on the floor (hiding it), cushions, back and arms."""
    d, h = rng.uniform(0.8, 0.95), rng.uniform(0.75, 0.9)
    return [(0, 0, 0.21, w, d, 0.42, rgb),
            (0, -0.08, 0.47, w - 0.36, d - 0.25, 0.1, rgb),
            (0, d / 2 - 0.1, 0.42 + (h - 0.42) / 2, w, 0.2, h - 0.42, rgb),
            (-(w / 2 - 0.09), 0, 0.52, 0.18, d, 0.2, rgb),
            (w / 2 - 0.09, 0, 0.52, 0.18, d, 0.2, rgb)]


def bookcase(rng: np.random.Generator, w: float, d: float, h: float, rgb: tuple) -> list[Part]:
    """Open shelves with books of random widths and colours, or a closed cabinet; back towards +y."""
    parts: list[Part] = []
    for sx in (-1, 1):
        parts.append((sx * (w / 2 - 0.01), 0, h / 2, 0.02, d, h, rgb))
    parts.append((0, d / 2 - 0.0075, h / 2, w - 0.04, 0.015, h, rgb))
    parts.append((0, -0.0075, h - 0.01, w - 0.04, d - 0.015, 0.02, rgb))
    parts.append((0, -0.0075, 0.04, w - 0.04, d - 0.015, 0.08, rgb))
    if rng.random() < 0.25:  # closed cabinet
        parts.append((0, -d / 2 + 0.01, h / 2 + 0.04, w - 0.04, 0.02, h - 0.1, rgb))
        return parts
    n = max(1, round((h - 0.1) / 0.36))
    levels = np.linspace(0.08, h - 0.02, n + 1)
    for z in levels[1:-1]:
        parts.append((0, -0.0075, z, w - 0.04, d - 0.04, 0.02, rgb))
    for a, b in zip(levels[:-1], levels[1:]):
        room = b - a - 0.03
        if room < 0.15 or rng.random() < 0.3:
            continue
        x = -w / 2 + 0.03
        while x < w / 2 - 0.1:
            bw = rng.uniform(0.08, 0.35)
            if x + bw > w / 2 - 0.03:
                break
            if rng.random() < 0.8:
                bh = rng.uniform(0.6, 0.95) * room
                parts.append((x + bw / 2, 0.01, a + 0.01 + bh / 2, bw, d - 0.08, bh, C.vivid(rng)))
            x += bw + 0.005
    return parts


def board(rng: np.random.Generator, w: float, h: float, bottom: float, rgb: tuple) -> list[Part]:
    """A thin board on a wall (back at +y) from ``bottom`` up, with a pen tray."""
    return [(0, 0.05 - 0.01, bottom + h / 2, w, 0.02, h, rgb),
            (0, 0.05 - 0.04, bottom - 0.01, 0.6 * w, 0.06, 0.02, C.METAL)]


def clutter(rng: np.random.Generator, kind: str, z: float = 0.0) -> tuple[list[Part], tuple[float, float]]:
    """A clutter object standing at height ``z``; also its footprint (w, d)."""
    rgb = C.vivid(rng)
    if kind == "monitor":
        sw = rng.uniform(0.45, 0.65)
        return [(0, 0.02, z + 0.01, 0.22, 0.18, 0.02, C.METAL), (0, 0.05, z + 0.08, 0.05, 0.04, 0.12, C.METAL),
                (0, 0.03, z + 0.14 + 0.17, sw, 0.04, 0.34, (25, 25, 28))], (sw, 0.2)
    if kind == "laptop":
        return [(0, 0, z + 0.01, 0.33, 0.23, 0.02, C.METAL), (0, 0.11, z + 0.12, 0.33, 0.01, 0.22, C.METAL)], (0.33, 0.24)
    if kind == "papers":
        w, d, h = rng.uniform(0.2, 0.35), rng.uniform(0.2, 0.3), rng.uniform(0.02, 0.15)
        return [(0, 0, z + h / 2, w, d, h, C.pick(rng, [(235, 235, 230), (220, 215, 190)]))], (w, d)
    if kind == "bin":
        return [(0, 0, z + 0.2, 0.3, 0.3, 0.4, rgb)], (0.3, 0.3)
    if kind == "box":
        s = rng.uniform(0.3, 0.6, 3)
        parts = [(0, 0, z + s[2] / 2, s[0], s[1], s[2], C.pick(rng, [(170, 130, 85), (190, 150, 100)]))]
        if rng.random() < 0.4:
            t = s * rng.uniform(0.6, 0.95, 3)
            parts.append((0, 0, z + s[2] + t[2] / 2, t[0], t[1], t[2], C.pick(rng, [(170, 130, 85)])))
        return parts, (s[0], s[1])
    if kind == "plant":
        p = rng.uniform(0.3, 0.45)
        f = rng.uniform(0.5, 0.8)
        fh = rng.uniform(0.6, 1.2)
        return [(0, 0, z + p / 2, p, p, p, rgb), (0, 0, z + p + fh / 2, f, f, fh, (50, 100, 45))], (f, f)
    if kind == "printer":
        return [(0, 0, z + 0.4, 0.5, 0.45, 0.35, (200, 200, 198)), (0, 0, z + 0.11, 0.45, 0.4, 0.22, C.METAL)], (0.5, 0.45)
    if kind == "cooler":
        return [(0, 0, z + 0.5, 0.32, 0.32, 1.0, (220, 220, 225)), (0, 0, z + 1.15, 0.26, 0.26, 0.3, (120, 160, 210))], \
            (0.32, 0.32)
    if kind == "toilet":
        return [(0, -0.05, z + 0.2, 0.38, 0.55, 0.4, (240, 240, 240)),
                (0, 0.22, z + 0.6, 0.4, 0.18, 0.4, (240, 240, 240))], (0.4, 0.7)
    raise ValueError(kind)


# -- placement -------------------------------------------------------------------------------
class Placer:
    """Free space of one room: clear footprint, wall edges with their openings, occupied 3-D boxes."""

    def __init__(self, rng: np.random.Generator, space: Space, walls: list[Wall], style: dict):
        self.rng, self.space, self.style = rng, space, style
        self.hard = None
        self.poly = Polygon(space.footprint)
        shapely.prepare(self.poly)
        lo, hi = space.footprint.min(0), space.footprint.max(0)
        self.rectangular = abs((hi - lo).prod() - self.poly.area) < 1e-6
        self.occupied = np.empty((0, 6))
        self.edges = []
        z0 = space.z0
        for a, b in footprint_edges(space):
            e = b - a
            length = float(np.hypot(*e))
            self.edges.append({"a": a, "e": e / length, "n": np.array([-e[1], e[0]]) / length, "len": length,
                               "openings": [(s0, s1, o) for s0, s1, o in edge_openings(space, walls, a, b)]})
        # keep doorways clear on this side (and the swing of leaves turning into this room)
        for ed in self.edges:
            for s0, s1, o in ed["openings"]:
                if o.kind == "door":
                    reach = 1.1 if o.leaf != "open" else (s1 - s0) / o.leaves + 0.3
                    self._block_strip(ed, s0 - 0.25, s1 + 0.25, max(reach, 1.0), z0, space.z1)
                else:  # only tall things (bookcases, not chairs) are kept off windows
                    self._block_strip(ed, s0 - 0.05, s1 + 0.05, 0.45, o.z0 + 0.2, o.z1)
        for e in space.elements:  # columns, beams, partial walls, lights, door leaves and casings
            for b in e.prims:
                if isinstance(b, Box):
                    self.occupy(b.corners())

    def _block_strip(self, ed, s0, s1, depth, z0, z1):
        a, e, n = ed["a"], ed["e"], ed["n"]
        pts = np.array([a + e * s0, a + e * s1, a + e * s0 + n * depth, a + e * s1 + n * depth])
        self.occupied = np.vstack([self.occupied, np.r_[pts.min(0), z0, pts.max(0), z1]])

    def occupy(self, corners: np.ndarray) -> None:
        self.occupied = np.vstack([self.occupied, np.r_[corners.min(0), corners.max(0)]])

    def fits(self, parts: list[Box], margin: float = 0.02) -> bool:
        corners = np.concatenate([b.corners() for b in parts])
        lo, hi = corners.min(0) + margin, corners.max(0) - margin
        o = self.occupied
        if len(o) and np.any((lo[0] < o[:, 3]) & (hi[0] > o[:, 0]) & (lo[1] < o[:, 4]) & (hi[1] > o[:, 1])
                             & (lo[2] < o[:, 5]) & (hi[2] > o[:, 2])):
            return False
        xy = corners[:, :2]
        if self.rectangular:
            flo, fhi = self.space.footprint.min(0), self.space.footprint.max(0)
            return bool(np.all(xy >= flo - 1e-9) and np.all(xy <= fhi + 1e-9))
        hull = shapely.convex_hull(shapely.multipoints(xy))
        return bool(self.poly.contains(hull))

    def build(self, parts: list[Part], xy, yaw: float, z: float = None) -> list[Box]:
        z = self.space.z0 if z is None else z
        c, s = math.cos(yaw), math.sin(yaw)
        out = []
        for cx, cy, cz, sx, sy, sz, rgb in parts:
            wx = xy[0] + c * cx - s * cy
            wy = xy[1] + s * cx + c * cy
            out.append(Box(np.array([wx, wy, z + cz]), np.array([sx, sy, sz], float), yaw, tuple(rgb)))
        return out

    def put(self, cls: str, parts: list[Part], xy, yaw: float, z: float = None, *, margin: float = 0.02,
            info: dict | None = None) -> Element | None:
        boxes = self.build(parts, xy, yaw, z)
        if not self.fits(boxes, margin):
            return None
        for b in boxes:
            self.occupy(b.corners())
        el = Element(-1, cls, self.space.id, boxes, yaw=yaw, info=info or {})
        self.space.elements.append(el)
        return el

    # wall positions
    def wall_spot(self, width: float, depth: float, height: float, gap: float = 0.02, bottom: float = 0.0,
                  edge: int | None = None):
        """A random spot against a wall: centre xy and yaw facing into the room (local +y to the wall)."""
        choices = [i for i, ed in enumerate(self.edges) if ed["len"] >= width + 0.1] if edge is None else [edge]
        if not choices:
            return None
        lens = np.array([self.edges[i]["len"] for i in choices])
        i = choices[int(self.rng.choice(len(choices), p=lens / lens.sum()))]
        ed = self.edges[i]
        s = self.rng.uniform(0.05, ed["len"] - width - 0.05) if ed["len"] - width > 0.1 else (ed["len"] - width) / 2
        for s0, s1, o in ed["openings"]:
            if s < s1 + 0.05 and s + width > s0 - 0.05 and (o.kind == "door" or bottom < o.z1 - self.space.z0
                                                          and bottom + height > o.z0 - self.space.z0):
                return None
        n = ed["n"]
        xy = ed["a"] + ed["e"] * (s + width / 2) + n * (gap + depth / 2)
        return xy, math.atan2(n[0], -n[1]), i

    def against_wall(self, cls: str, make, width: float, depth: float, height: float, *, tries: int = 12,
                     bottom: float = 0.0, gap: float = 0.02, edge: int | None = None, info=None) -> Element | None:
        for _ in range(tries):
            spot = self.wall_spot(width, depth, height, gap, bottom, edge)
            if spot is None:
                continue
            el = self.put(cls, make(), spot[0], spot[1], info=info)
            if el is not None:
                return el
        return None

    def free_spot(self, tries: int, place) -> Element | None:
        lo, hi = self.space.footprint.min(0), self.space.footprint.max(0)
        for _ in range(tries):
            xy = self.rng.uniform(lo, hi)
            el = place(xy)
            if el is not None:
                return el
        return None


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
        from engine.synth.hard import furniture as hard_furniture

        hard_furniture.before(p, walls, hard)
    _radiators(p, walls)
    {"office": _office, "conferenceRoom": _conference, "hallway": _hallway, "lobby": _lobby,
     "storage": _storage, "WC": _wc, "openspace": _openspace, "stairs": _stairs}[space.type](p)
    _wall_clutter(p)
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
        p.put("chair", chair(rng, C.pick(rng, C.CHAIRS)), cxy, th + math.pi + rng.uniform(-0.4, 0.4))
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
    p.against_wall("board", lambda: board(rng, w, h, bottom, rgb), w, 0.1, h, bottom=bottom, gap=0.0, edge=edge)


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
                    p.put("chair", chair(rng, rgb), xy, face + rng.uniform(-0.3, 0.3))
        for sgn in (-1, 1):
            if rng.random() < 0.5:
                xy = centre + ax * sgn * (L / 2 + 0.4)
                p.put("chair", chair(rng, rgb), xy, yaw + (-math.pi / 2 if sgn > 0 else math.pi / 2))
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
            p.against_wall("chair", lambda: chair(rng, C.pick(rng, C.CHAIRS)), 0.56, 0.56, 1.0, gap=0.05)


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
        p.free_spot(10, lambda xy: p.put("chair", chair(rng, C.pick(rng, C.CHAIRS)), xy, rng.uniform(-math.pi, math.pi)))
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
                from engine.synth.hard.furniture import cubicle

                cubicle(p, np.array([x, y]), yaw, w, d)
            for sgn in (1, -1):
                xy = np.array([x, y]) + ax * sgn * (d / 2 + (0.04 if pods else 0.01))
                _desk_with_chair(p, free_xy=xy, yaw=yaw + (0 if sgn < 0 else math.pi))
    _bookcases(p, int(rng.integers(1, 4)))
    for _ in range(int(rng.integers(1, 3))):
        _board(p)
    _floor_clutter(p, int(rng.integers(2, 5)), kinds=("plant", "bin", "printer", "box"))
    if rng.random() < 0.3:
        p.against_wall("sofa", lambda: sofa(rng, 2.0, C.pick(rng, C.SOFAS)), 2.0, 0.95, 0.9)
