"""Hard scan conditions in the plan of a building (see :mod:`engine.synth.hard.hardness` for the list).

Layout (before walls): a large open space merged from a run of rooms
(``open_plan``); the floor's polygons (:class:`Geometry`): a wing at an angle
joined to the main hallway by a link with diagonal walls (``wing``), a
chamfered and a rounded building corner and one slanted or curved wall between
two rooms per floor (``oblique``), a stair tower at the west end of the main
hallway (``stairs``).

Walls (after they are found): very thin and very thick walls (``walls``),
glazed partitions (``glass``), walls lined by tall furniture (``hidden_walls``).
Spaces: the rooms never scanned (``unscanned``), hallway ceilings above the
rooms' (``bottlenecks``), the registration error of every space's scan and of
each scan position (``registration``), and the rates of sensor artefacts
(``artefacts``).  Everything draws from the difficulty's own stream
(:func:`engine.synth.hard.hardness.hard_rng`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon, box
from shapely.ops import split

from engine.synth.building import Space, Wall
from engine.synth.hard.hardness import Hardness, hard_rng
from engine.synth.layout import CIRCULATION, Draft, FloorLayout, floor_layout
from engine.synth.shapes import line_key, rotate_xy

#: Room types that may be glazed, lined or left unscanned.
ROOMS = ("office", "conferenceRoom", "openspace", "storage", "WC")


# -- layout ------------------------------------------------------------------------------------
def large_open_space(rng: np.random.Generator, lay: FloorLayout, level: float) -> None:
    """Merge a run of 3-6 simple rooms of a row (12-30 m) into one open space without partial walls."""
    if rng.random() > min(1.0, 0.85 * level):
        return
    rooms = sorted((i for i, d in enumerate(lay.drafts) if d.simple and d.type == "room"),
                   key=lambda i: (lay.drafts[i].row, lay.drafts[i].cells[0][0]))
    runs: list[list[int]] = []
    for i in rooms:
        d = lay.drafts[i]
        if runs:
            prev = lay.drafts[runs[-1][-1]]
            if prev.row == d.row and abs(prev.cells[0][2] - d.cells[0][0]) < 1e-6:
                runs[-1].append(i)
                continue
        runs.append([i])
    options = []
    for run in runs:
        for a in range(len(run)):
            for b in range(a + 3, min(len(run), a + 6) + 1):
                width = lay.drafts[run[b - 1]].cells[0][2] - lay.drafts[run[a]].cells[0][0]
                if 12.0 <= width <= 30.0:
                    options.append(run[a:b])
    if not options:
        return
    pick = options[int(rng.integers(len(options)))]
    first, last = lay.drafts[pick[0]], lay.drafts[pick[-1]]
    x0, y0, _, y1 = first.cells[0]
    x1 = last.cells[0][2]
    first.type, first.cells, first.partials, first.simple = "openspace", [(x0, y0, x1, y1)], [], False
    for j in sorted(pick[1:], reverse=True):
        lay.drafts.pop(j)


def _band_halls(lay: FloorLayout) -> list[Draft]:
    """The hallway drafts that run along x (not the cross hallways), lowest first."""
    out = []
    for d in lay.drafts:
        if d.type != "hallway" or len(d.cells) != 1:
            continue
        x0, y0, x1, y1 = d.cells[0]
        if x1 - x0 > y1 - y0:
            out.append(d)
    return sorted(out, key=lambda d: (d.cells[0][1], d.cells[0][0]))


@dataclass
class Geometry:
    """The non-rectangular features of every floor of a building (the same outline on all floors)."""

    length: float
    depth: float
    wing: dict | None = None
    chamfer: float | None = None
    rounded: float | None = None
    stairs: tuple[float, float, float, float] | None = None
    wing_layouts: list[FloorLayout] = field(default_factory=list)
    slant_level: float = 0.0
    seed: int = 0

    @classmethod
    def plan(cls, seed: int, h: Hardness, layouts: list[FloorLayout], area_per_floor: float) -> Geometry:
        L, D = layouts[0].length, layouts[0].depth
        g = cls(L, D, seed=seed)
        if h.on("oblique"):
            rng = hard_rng(seed, "oblique", 0)
            lvl = min(h.level("oblique"), 1.5)
            bottom = min(r.y1 - r.y0 for lay in layouts for r in lay.rows if r.y0 < 1e-6) if all(
                any(r.y0 < 1e-6 for r in lay.rows) for lay in layouts) else 0.0
            top = min(r.y1 - r.y0 for lay in layouts for r in lay.rows if abs(r.y1 - lay.depth) < 1e-6) if all(
                any(abs(r.y1 - lay.depth) < 1e-6 for r in lay.rows) for lay in layouts) else 0.0
            c = min(rng.uniform(1.5, 3.0) * lvl, 0.7 * bottom, 0.3 * L)
            r = min(rng.uniform(2.0, 3.5) * lvl, 0.7 * top, 0.3 * L)
            g.chamfer = round(c, 3) if c >= 1.0 else None
            g.rounded = round(r, 3) if r >= 1.2 else None
            g.slant_level = h.level("oblique")
        if h.on("stairs") and len(layouts) > 1:
            rng = hard_rng(seed, "stairs", 0)
            hall = _band_halls(layouts[0])
            yc = (hall[0].cells[0][1] + hall[0].cells[0][3]) / 2 if hall else D / 2
            width = round(float(rng.uniform(2.8, 3.1)), 3)
            run = round(float(rng.uniform(5.3, 5.9)), 3)
            y0 = float(np.clip(yc - width / 2, 0.0, D - width))
            g.stairs = (-run, round(y0, 3), 0.0, round(y0 + width, 3))
        if h.on("wing"):
            g._plan_wing(seed, h.level("wing"), layouts, area_per_floor)
        return g

    # -- the wing ----------------------------------------------------------------------------------
    def _plan_wing(self, seed: int, level: float, layouts: list[FloorLayout], area: float) -> None:
        rng = hard_rng(seed, "wing", 0)
        halls = [d for d in _band_halls(layouts[0]) if abs(d.cells[0][2] - self.length) < 1e-6]
        if not halls:
            return
        my0, my1 = halls[0].cells[0][1], halls[0].cells[0][3]
        share = float(np.clip(0.3 * level, 0.15, 0.45))
        area_w = float(np.clip(share * area, 80.0, 1500.0))
        lays = []
        for f in range(len(layouts)):
            outline = None if f == 0 else (lays[0].length, lays[0].depth)
            lays.append(floor_layout(hard_rng(seed, "wing", 1, f), area_w, lobby=False, outline=outline))
        whalls = [d for d in _band_halls(lays[0]) if d.cells[0][0] < 1e-6]
        if not whalls:
            return
        wy0, wy1 = whalls[0].cells[0][1], whalls[0].cells[0][3]
        sign = 1.0 if rng.random() < 0.5 else -1.0
        theta = sign * math.radians(rng.uniform(15.0, 40.0) * min(1.0, max(level, 0.5)))
        wc, mc = (wy0 + wy1) / 2, (my0 + my1) / 2
        rect = np.array([[0, 0], [lays[0].length, 0], [lays[0].length, lays[0].depth], [0, lays[0].depth]], float)
        main = box(0.0, 0.0, self.length, self.depth)
        gap = 0.8
        while gap < 30.0:
            q = np.array([self.length, mc]) + gap * np.array([math.cos(theta), math.sin(theta)])
            poly = Polygon(rotate_xy(rect - [0.0, wc], theta) + q)
            if not poly.buffer(0.6).intersects(main):
                break
            gap += 0.1
        self.wing = {"theta": theta, "q": q.tolist(), "wc": wc, "gap": gap}
        self.wing_layouts = lays

    def wing_xy(self, xy: np.ndarray) -> np.ndarray:
        """Wing-local points -> the floor's frame."""
        w = self.wing
        return rotate_xy(np.asarray(xy, float) - [0.0, w["wc"]], w["theta"]) + np.asarray(w["q"])

    # -- one floor -----------------------------------------------------------------------------------
    def floor(self, f: int, lay: FloorLayout) -> list[Draft]:
        """The floor's drafts with their polygons: the layout's, then the wing's and the stair tower."""
        drafts = list(lay.drafts)
        for d in drafts:
            d.poly = shapely.union_all([box(*c) for c in d.cells])
        if self.slant_level > 0:
            _slant(hard_rng(self.seed, "oblique", 1, f), drafts, lay, self.slant_level)
        outline = self.outline()
        for d in drafts:
            if outline is not None:
                d.poly = d.poly.intersection(outline)
                if d.poly.geom_type != "Polygon":
                    d.poly = max(getattr(d.poly, "geoms", [d.poly]), key=lambda g: g.area)
        if self.wing is not None:
            drafts += self._wing_drafts(f, lay)
        if self.stairs is not None:
            x0, y0, x1, y1 = self.stairs
            drafts.append(Draft("stairs", [self.stairs], simple=False, poly=box(x0, y0, x1, y1)))
        return drafts

    def outline(self) -> Polygon | None:
        """The main block's outline: its rectangle less the chamfered and the rounded corner."""
        if self.chamfer is None and self.rounded is None:
            return None
        shape = box(0.0, 0.0, self.length, self.depth)
        if self.chamfer:
            c = self.chamfer
            shape = shape.difference(Polygon([(-1, -1), (c + 1e-9, -1), (c, 0), (0, c), (-1, c + 1e-9)]))
        if self.rounded:
            r, D = self.rounded, self.depth
            disc = Point(r, D - r).buffer(r, quad_segs=12)
            corner = box(-1.0, D - r, r, D + 1.0).difference(disc)
            shape = shape.difference(corner)
        return shapely.set_precision(shape, 1e-6)

    def _wing_drafts(self, f: int, lay: FloorLayout) -> list[Draft]:
        wlay = self.wing_layouts[f]
        theta = self.wing["theta"]
        out = []
        halls = [d for d in _band_halls(lay) if abs(d.cells[0][2] - self.length) < 1e-6]
        whalls = [d for d in _band_halls(wlay) if d.cells[0][0] < 1e-6]
        link_to = whalls[0] if whalls and halls else None
        for d in wlay.drafts:
            corners = [np.array([[c[0], c[1]], [c[2], c[1]], [c[2], c[3]], [c[0], c[3]]]) for c in d.cells]
            polys = [Polygon(self.wing_xy(q)) for q in corners]
            poly = shapely.union_all(polys)
            local = [rotate_xy(self.wing_xy(q), -theta) for q in corners]
            cells = [(float(q[:, 0].min()), float(q[:, 1].min()), float(q[:, 0].max()), float(q[:, 1].max()))
                     for q in local]
            partials = [tuple(map(tuple, self.wing_xy(np.array([p, q])))) for p, q in d.partials]
            if d is link_to:
                my0, my1 = halls[0].cells[0][1], halls[0].cells[0][3]
                wy0, wy1 = d.cells[0][1], d.cells[0][3]
                ends = np.r_[[[self.length, my0], [self.length, my1]], self.wing_xy(np.array([[0, wy0], [0, wy1]]))]
                link = shapely.convex_hull(shapely.multipoints(ends))
                poly = shapely.union_all([poly, link])
                if poly.geom_type != "Polygon":
                    poly = max(poly.geoms, key=lambda g: g.area)
            poly = shapely.set_precision(poly, 1e-6)
            out.append(Draft(d.type, cells, partials=partials, row=-1, simple=False, poly=poly, axis=theta))
        return out


def _slant(rng: np.random.Generator, drafts: list[Draft], lay: FloorLayout, level: float) -> None:
    """One pair of neighbouring rooms of a row gets a slanted or curved wall between them."""
    if rng.random() > min(1.0, level):
        return
    simple = [(i, d.cells[0]) for i, d in enumerate(drafts) if d.simple and d.type == "room" and len(d.cells) == 1]
    pairs = []
    for i, a in simple:
        for j, b in simple:
            if drafts[i].row == drafts[j].row and abs(a[2] - b[0]) < 1e-6 and min(a[2] - a[0], b[2] - b[0]) >= 3.0:
                pairs.append((i, j))
    if not pairs:
        return
    i, j = pairs[int(rng.integers(len(pairs)))]
    (x0, y0, xm, y1), (_, _, x1, _) = drafts[i].cells[0], drafts[j].cells[0]
    whole = box(x0, y0, x1, y1)
    room = min(xm - x0, x1 - xm) - 1.2
    if rng.random() < 0.6:  # slanted: 10-30 degrees off the row's cross direction
        delta = min(math.tan(math.radians(rng.uniform(10, 30))) * (y1 - y0), 2 * room) * rng.choice([-1.0, 1.0])
        p, q = np.array([xm - delta / 2, y0]), np.array([xm + delta / 2, y1])
        cut = LineString([p - 0.2 * (q - p), q + 0.2 * (q - p)])
    else:  # curved: an arc bulging 0.5-1.2 m into one of the rooms
        sag = min(rng.uniform(0.5, 1.2), room) * rng.choice([-1.0, 1.0])
        t = np.linspace(0.0, 1.0, 13)
        ys = y0 + (y1 - y0) * t
        xs = xm + sag * np.sin(np.pi * t)
        cut = LineString(np.r_[[[xm, y0 - 1.0]], np.c_[xs, ys], [[xm, y1 + 1.0]]])
    parts = sorted(split(whole, cut).geoms, key=lambda g: g.centroid.x)
    if len(parts) != 2:
        return
    drafts[i].poly, drafts[j].poly = (shapely.set_precision(p, 1e-6) for p in parts)
    drafts[i].simple = drafts[j].simple = False


# -- walls ----------------------------------------------------------------------------------------
def thin_and_thick(rng: np.random.Generator, walls: list[Wall], level: float, exterior: float | None) -> bool:
    """Drywall (0.06-0.09 m) and structural (0.35-0.7 m) interior walls, per wall line; thick exterior walls."""
    lines: dict[tuple, list[Wall]] = {}
    for w in walls:
        if w.kind == "interior" and w.material == "solid":
            lines.setdefault(line_key(np.asarray(w.p0), np.asarray(w.p1)), []).append(w)
    changed = False
    for key in sorted(lines):
        r = rng.random()
        if r < 0.3 * level:
            t = round(float(rng.uniform(0.06, 0.09)), 3)
        elif r < 0.5 * level:
            t = round(float(rng.uniform(0.35, 0.7)), 3)
        else:
            continue
        for w in lines[key]:
            w.thickness = t
        changed = True
    if exterior is not None:
        for w in walls:
            if w.kind == "exterior":
                w.thickness = exterior
                changed = True
    return changed


def glass_walls(rng: np.random.Generator, walls: list[Wall], spaces: list[Space], level: float) -> bool:
    """Glazed partitions between a room and a hallway or two rooms (whole walls between the pair)."""
    pairs: dict[tuple[int, int], list[Wall]] = {}
    for w in walls:
        if w.kind != "interior" or w.material != "solid":
            continue
        types = {spaces[w.left].type, spaces[w.right].type}
        if not types <= {"office", "conferenceRoom", "openspace", "hallway", "lobby"} or types <= set(CIRCULATION):
            continue
        if not (spaces[w.left].scanned and spaces[w.right].scanned):
            continue
        pairs.setdefault(tuple(sorted((w.left, w.right))), []).append(w)
    changed = False
    for key in sorted(pairs):
        ws = pairs[key]
        if sum(w.length for w in ws) < 1.5 or rng.random() > 0.25 * level:
            continue
        t = round(float(rng.uniform(0.08, 0.12)), 3)
        r = rng.random()
        lo = 0.05 if r < 0.6 else float(rng.uniform(0.85, 1.05))
        hi = None if r < 0.85 else float(rng.uniform(2.1, 2.3))
        for w in ws:
            w.material, w.thickness = "glass", t
            top = w.z1 - w.z0 - 0.05
            w.glazing = (round(lo, 3), round(min(top, hi) if hi is not None else top, 3))
        changed = True
    return changed


def line_walls(rng: np.random.Generator, walls: list[Wall], spaces: list[Space], level: float) -> None:
    """Walls to be hidden by tall furniture: ``Wall.lined`` lists the spaces whose face is lined."""
    rooms = ("office", "conferenceRoom", "storage", "openspace")
    for w in walls:
        if w.kind != "interior" or w.material != "solid" or w.length < 2.5:
            continue
        sides = [s for s in (w.left, w.right) if spaces[s].type in rooms and spaces[s].scanned]
        if not sides:
            continue
        both_rooms = len(sides) == 2
        if rng.random() > (0.35 if both_rooms else 0.12) * level:
            continue
        if both_rooms and rng.random() < 0.5:
            w.lined = tuple(sides)
        else:
            w.lined = (sides[int(rng.integers(len(sides)))],)


# -- spaces --------------------------------------------------------------------------------------
def choose_unscanned(rng: np.random.Generator, floor_spaces: list[Space], areas: dict[int, float],
                     level: float) -> set[int]:
    """Rooms of a floor never scanned: small storage rooms, WCs or offices (one, two on big floors)."""
    by_id = {s.id: s for s in floor_spaces}
    cands = [s.id for s in floor_spaces if s.type in ("storage", "WC", "office") and areas.get(s.id, 99.0) <= 25.0]
    if not cands:
        return set()
    n = int(np.floor(level * (2 if len(floor_spaces) > 15 else 1) + rng.random() * 0.5))
    cands.sort(key=lambda i: (by_id[i].type != "storage", i))
    picked: set[int] = set()
    for i in cands:
        if len(picked) >= n:
            break
        if rng.random() < 0.8 or by_id[i].type == "storage":
            picked.add(i)
    for i in picked:
        by_id[i].scanned = False
    return picked


def registration(rng: np.random.Generator, space: Space, level: float) -> None:
    """The rigid registration error of the space's scan and the residual one of each scan position."""
    fp = space.footprint
    centre = fp.mean(0)
    t = np.clip(rng.normal(0.0, 0.02 * level, 3), -0.05 * level, 0.05 * level)
    t[2] *= 0.5
    angle = math.radians(rng.uniform(-0.4, 0.4) * level)
    space.registration = (float(t[0]), float(t[1]), float(t[2]), angle, float(centre[0]), float(centre[1]))
    k = len(space.scanners)
    jit = np.c_[rng.uniform(-0.012, 0.012, (k, 3)) * level, np.radians(rng.uniform(-0.08, 0.08, k) * level)]
    if k:
        jit[0] = 0.0  # the first scan position is the reference of the space's scan
    space.scan_jitter = jit
    lo, hi = fp.min(0), fp.max(0)
    corners = np.array([[lo[0], lo[1]], [lo[0], hi[1]], [hi[0], lo[1]], [hi[0], hi[1]]])
    reach = np.max(np.hypot(*(corners[None, :, :] - space.scanners[:, None, :2]).transpose(2, 0, 1)), axis=1) \
        if k else np.zeros(0)
    space.jitter_bound = float(np.max(np.linalg.norm(jit[:, :3], axis=1) + np.abs(jit[:, 3]) * (reach + 1.0))) \
        if k else 0.0


def floor_outline(spaces: list[Space], walls: list[Wall], floor: int) -> np.ndarray:
    """The outer polygon of a floor (spaces and wall bodies), local xy."""
    geoms = [Polygon(s.footprint) for s in spaces if s.floor == floor]
    geoms += [Polygon(w.body()) for w in walls if w.floor == floor]
    u = shapely.union_all(geoms).buffer(0.05, join_style="mitre")
    if u.geom_type != "Polygon":
        u = max(u.geoms, key=lambda g: g.area)
    return np.asarray(u.exterior.coords)[:-1]
