"""The plan of a whole building: floors of spaces, walls with doors and windows, and every element.

:func:`plan_building` is deterministic for a seed: each floor's layout, each
space's furniture and each part's scan draw from their own random stream
(``numpy.random.SeedSequence(seed, spawn_key=(stage, id...))``), so nothing
depends on the order in which dask runs the tasks.

Steps per floor: a layout of centre-line cells (:mod:`engine.synth.layout`);
walls where cells of different spaces (or the outside) meet, one thickness per
wall line; clear footprints (cells minus wall bodies); doors chosen so that
every space of the floor is reachable from its hallways; windows on exterior
walls; then per space the structural elements (:mod:`engine.synth.structure`),
the furniture (:mod:`engine.synth.furniture`) and the scan positions.
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import shapely
from shapely.geometry import box

from engine import config
from engine.synth import colours, furniture, shapes, structure
from engine.synth.building import Building, Element, FloorInfo, Frame, Opening, PartSpec, Space, Wall
from engine.synth.hard import plan as hard_plan
from engine.synth.hard.elements import stair_scanners
from engine.synth.hard.hardness import HardContext, Hardness, hard_rng
from engine.synth.layout import CIRCULATION, Draft, floor_layout
from tiles.errors import UserError

#: Random-stream keys (first element of every spawn_key).
S_BUILDING, S_FLOOR, S_SPACE, S_SCAN = 0, 1, 2, 3

#: Average floor area per space, used to turn ``rooms`` into an area.
AREA_PER_SPACE = 31.0
MIN_AREA_PER_FLOOR = 40.0


def rng_for(seed: int, *key: int) -> np.random.Generator:
    """The random stream of one stage of one object, independent of every other."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key)))


def check_parameters(*, area_m2: float | None = None, rooms: int | None = None, floors: int = 1,
                     density: float | None = None, yaw: float = 0.0,
                     offset=(0.0, 0.0, 0.0), hardness=None) -> tuple[float | None, float]:
    """Refuse impossible building parameters with a one-line :class:`UserError`; returns area and density.

    Cheap: the command line calls it before it starts a cluster.
    """
    Hardness.parse(hardness)
    floors = int(floors)
    if floors < 1:
        raise UserError(None, f"floors must be at least 1, not {floors}")
    if rooms is not None and int(rooms) < 2 * floors:
        raise UserError(None, f"rooms must be at least two per floor (a hallway and a room): "
                              f"{2 * floors} for {floors} floor(s), not {rooms}")
    density = config.setting("synth.density") if density is None else float(density)
    if not (density > 0 and math.isfinite(density)):
        raise UserError(None, f"density must be a positive number of points per m^2, not {density}")
    if area_m2 is not None:
        area_m2 = float(area_m2)
        if not (math.isfinite(area_m2) and area_m2 >= MIN_AREA_PER_FLOOR * floors):
            raise UserError(None, f"area must be at least {MIN_AREA_PER_FLOOR:g} m^2 per floor, not {area_m2:g} m^2 "
                                  f"for {floors} floor(s)")
    if len(offset) != 3 or not all(math.isfinite(float(v)) for v in offset):
        raise UserError(None, f"offset must be three finite numbers, not {tuple(offset)}")
    if not math.isfinite(float(yaw)):
        raise UserError(None, f"yaw must be a finite number of degrees, not {yaw}")
    return area_m2, density


def plan_building(seed: int = 0, *, area_m2: float | None = None, rooms: int | None = None, floors: int = 1,
                  density: float | None = None, yaw: float = 0.0,
                  offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  part_points: int | None = None, hardness=None) -> Building:
    """Plan a building: spaces with footprints, walls with openings, elements with boxes.

    Parameters
    ----------
    seed
        Everything follows from it.
    area_m2
        Gross floor area of the whole building (all floors, wall centre lines).
    rooms
        Number of spaces of the whole building (hallways and lobby included);
        met exactly when room sizes allow.  With ``area_m2`` too, the area sets
        the footprint and ``rooms`` the count.  Neither: ``buildingparser.synth.area-m2``.
    floors
        Storeys, stacked with a slab and a ceiling void between them.
    density
        Points per m^2 of scanned surface before the per-space factor (x0.5-x2);
        default ``buildingparser.synth.density``.
    yaw
        Rotation of the building about the vertical (degrees).
    offset
        World position of the local origin (e.g. UTM ``500000 4100000 30``).
    part_points
        Largest estimated point count of one scan task; a bigger space is cut into pieces.
    hardness
        The difficulties of real scans to add (:mod:`engine.synth.hard.hardness`): a
        :class:`~engine.synth.hard.hardness.Hardness`, ``"all"``, ``"glass,wing"``, a
        list of names or ``{name: level}``; None: a clean building.
    """
    area_m2, density = check_parameters(area_m2=area_m2, rooms=rooms, floors=floors, density=density, yaw=yaw,
                                        offset=offset, hardness=hardness)
    h = Hardness.parse(hardness)
    hard = HardContext(h, int(seed)) if h else None
    floors = int(floors)
    area_given = area_m2 is not None
    if area_m2 is None:
        area_m2 = (max(float(rooms) * AREA_PER_SPACE, MIN_AREA_PER_FLOOR * floors) if rooms is not None
                   else config.setting("synth.area-m2"))
    part_points = int(part_points or config.setting("synth.part-points"))
    frame = Frame(math.radians(float(yaw)), tuple(float(v) for v in offset))

    brng = rng_for(seed, S_BUILDING)
    style = colours.building_style(brng)
    ext_t = round(brng.uniform(0.25, 0.35), 3)
    layouts = _floor_layouts(seed, floors, area_m2, rooms, area_given)
    length, depth = layouts[0].length, layouts[0].depth
    if h.on("open_plan"):
        for f, lay in enumerate(layouts):
            hard_plan.large_open_space(hard_rng(seed, "open_plan", 0, f), lay, h.level("open_plan"))
    geo = hard_plan.Geometry.plan(int(seed), h, layouts, area_m2 / floors) if h.geometric else None
    ext_hard = None
    if h.on("walls") and hard_rng(seed, "walls", 1000).random() < 0.5 * h.level("walls"):
        ext_hard = round(float(hard_rng(seed, "walls", 1001).uniform(0.4, 0.7)), 3)

    spaces: list[Space] = []
    walls: list[Wall] = []
    openings: list[Opening] = []
    floor_infos: list[FloorInfo] = []
    counters: dict[str, int] = defaultdict(int)
    z = 0.0
    for f in range(floors):
        frng = rng_for(seed, S_FLOOR, f, 1000)
        lay = layouts[f]
        base_h = round(frng.uniform(2.7, 3.3), 3)
        first = len(spaces)
        fdrafts = geo.floor(f, lay) if geo is not None else lay.drafts
        for d in fdrafts:
            spaces.append(_new_space(d, len(spaces), f, z, base_h, frng, counters))
            if h.on("bottlenecks") and spaces[-1].type == "hallway":
                lift = hard_rng(seed, "bottlenecks", 0, spaces[-1].id).uniform(0.3, 0.8) * h.level("bottlenecks")
                spaces[-1].z1 = round(z + min(4.2, base_h + lift), 3)
        drafts = {first + i: d for i, d in enumerate(fdrafts)}
        _ensure_wc(spaces[first:], counters)
        closed: set[int] = set()
        if h.on("unscanned"):
            closed = hard_plan.choose_unscanned(hard_rng(seed, "unscanned", f), spaces[first:],
                                                {sid: d.area for sid, d in drafts.items()}, h.level("unscanned"))
        if geo is not None:
            polys = {sid: d.poly for sid, d in drafts.items()}
            floor_walls = shapes.walls_from_polygons(polys, {sid: d.partials for sid, d in drafts.items()
                                                             if d.partials}, f, z, spaces, _thickness_draw(frng),
                                                     ext_t, len(walls))
        else:
            floor_walls = _walls(drafts, f, z, spaces, frng, ext_t, len(walls), length, depth)
        changed = False
        if h.on("walls"):
            changed |= hard_plan.thin_and_thick(hard_rng(seed, "walls", f), floor_walls, h.level("walls"), ext_hard)
        if h.on("glass"):
            changed |= hard_plan.glass_walls(hard_rng(seed, "glass", f), floor_walls, spaces, h.level("glass"))
        if changed:
            shapes.joint_reach(floor_walls)
        walls.extend(floor_walls)
        if geo is None:  # Manhattan plan: each space's polygon is the union of its cells
            polys = {sid: shapely.union_all([box(*c) for c in d.cells]) for sid, d in drafts.items()}
        shapes.clear_footprints(polys, floor_walls, spaces)
        _doors(frng, floor_walls, spaces, openings, drafts, exterior_door=(f == 0), closed=closed)
        _windows(frng, floor_walls, spaces, openings, style)
        if h.on("hidden_walls"):
            hard_plan.line_walls(hard_rng(seed, "hidden_walls", f), floor_walls, spaces, h.level("hidden_walls"))
        ceiling_max = max(spaces[i].z1 for i in drafts if spaces[i].type != "stairs") - z
        plenum = frng.uniform(0.1, 0.6)
        slab = frng.uniform(0.2, 0.4)
        nxt = round(z + ceiling_max + plenum + slab, 3)
        top = f == floors - 1
        for sid in drafts:
            if spaces[sid].type == "stairs":
                _stair_heights(spaces[sid], floor_walls, spaces, nxt, top, f, slab)
        floor_infos.append(FloorInfo(f, z, z + ceiling_max, (nxt - slab, nxt if not top else nxt - slab)))
        z = nxt

    for w in walls:
        for o in w.openings:
            for s in (w.left, w.right):
                if s >= 0:
                    (spaces[s].doors if o.kind == "door" else spaces[s].windows).append(o.id)
        for s in {w.left, w.right} - {-1}:
            spaces[s].walls.append(w.id)
    for s in spaces:
        s.doors, s.windows = sorted(set(s.doors)), sorted(set(s.windows))
    # elements, per space from its own random stream
    for s in spaces:
        srng = rng_for(seed, S_SPACE, s.id)
        colours.space_colours(srng, s, style)
        shapes.in_local_frame(s, walls, lambda lw: structure.add_structure(srng, s, lw, openings, style, hard=hard))
        shapes.in_local_frame(s, walls, lambda lw: furniture.furnish(srng, s, lw, openings, style, hard=hard))
        if s.scanned and s.stairs is not None:
            shapes.in_local_frame(s, walls, lambda lw: stair_scanners(s, hard_rng(seed, "stairs", 1, s.id)))
        elif s.scanned:
            shapes.in_local_frame(s, walls, lambda lw: structure.place_scanners(srng, s))
        else:
            s.scanners = np.zeros((0, 3))
    if hard is not None:
        _hard_spaces(hard, spaces, walls)
    next_id = 0
    for s in spaces:
        for e in s.elements:
            e.id = next_id
            next_id += 1
            e.fit_box(s.noise_bound + 1e-3 + s.jitter_bound)
        for e in s.elements:
            if e.cls == "door":
                openings[e.info["opening"]].elements.append(e.id)
            elif e.cls == "window":
                openings[e.info["opening"]].elements.append(e.id)
    params = {"seed": int(seed), "area_m2": area_m2, "rooms": rooms, "floors": floors, "density": density,
              "part_points": part_points, "generator": "engine.synth"}
    if h:
        params["hardness"] = h.to_dict()
    b = Building(int(seed), frame, density, spaces, walls, openings, floor_infos, params=params)
    b.parts = plan_parts(b, part_points)
    return b


def _thickness_draw(rng: np.random.Generator):
    """Interior wall thickness per wall line (0.1-0.22 m; partial walls 0.1-0.15 m), drawn once per line."""
    drawn: dict = {}

    def draw(key) -> float:
        if key not in drawn:
            lo, hi = (0.1, 0.15) if key[0] == "partial" else (0.1, 0.22)
            drawn[key] = round(float(rng.uniform(lo, hi)), 3)
        return drawn[key]
    return draw


def _stair_heights(sp: Space, walls: list[Wall], spaces: list[Space], nxt: float, top: bool, floor: int,
                   slab: float) -> None:
    """A stair tower's space of one floor reaches the next floor's level (its flight rises through the slab)."""
    rise = nxt - sp.z0
    if not top:
        sp.z1 = nxt
        for w in walls:
            if sp.id in (w.left, w.right):
                w.z1 = max(spaces[s].z1 for s in (w.left, w.right) if s >= 0)
    sp.stairs = {"rise": round(rise, 3), "top": top, "below": floor > 0, "slab": round(slab, 3)}


def _hard_spaces(hard: HardContext, spaces: list[Space], walls: list[Wall]) -> None:
    """Per-space difficulties that need the whole plan: registration errors, sensor artefacts."""
    outlines: dict[int, np.ndarray] = {}
    for s in spaces:
        if not s.scanned:
            continue
        if hard.on("registration"):
            hard_plan.registration(hard.rng("registration", s.id), s, hard.level("registration"))
        if hard.on("artefacts"):
            lvl = hard.level("artefacts")
            s.flying, s.ghosts = 0.3 * lvl, 0.04 * lvl
            if s.floor not in outlines:
                outlines[s.floor] = hard_plan.floor_outline(spaces, walls, s.floor)
            s.outline = outlines[s.floor]
            lo, hi = s.footprint.min(0), s.footprint.max(0)
            centre = np.r_[(lo + hi) / 2, (s.z0 + s.z1) / 2]
            vol = Element(-1, "clutter", s.id, [], center=centre, size=np.r_[hi - lo, s.z1 - s.z0],
                          info={"kind": "flying"})
            s.elements.append(vol)


def _floor_layouts(seed: int, floors: int, area_m2: float, rooms: int | None, area_given: bool) -> list:
    """One layout per floor, all on the ground floor's outline, each with its share of ``rooms`` if given.

    When only ``rooms`` is given, the ground floor's area is adjusted (a few
    tries) until the layout can hold its share; upper floors retry with new draws.
    """
    targets = [rooms // floors + (1 if f < rooms % floors else 0) for f in range(floors)] if rooms else [None] * floors
    layouts: list = []
    area = area_m2 / floors
    outline = None
    for f, target in enumerate(targets):
        best = None
        for attempt in range(12):
            lay = floor_layout(rng_for(seed, S_FLOOR, f, attempt), area, target=target, lobby=(f == 0),
                               outline=outline)
            n = len(lay.drafts)
            if best is None or abs(n - target) < abs(len(best.drafts) - target):
                best = lay
            if target is None or n == target:
                break
            if outline is None and not area_given:
                area = max(area * float(np.clip(target / n, 0.8, 1.3)), MIN_AREA_PER_FLOOR)
        layouts.append(best)
        outline = (best.length, best.depth)
    return layouts


def _room_type(rng: np.random.Generator, d: Draft) -> str:
    if d.type in ("hallway", "lobby", "openspace", "stairs"):
        return d.type
    area, width = d.area, d.width
    if d.type == "room_small":
        return str(rng.choice(["storage", "WC", "office"], p=[0.4, 0.3, 0.3]))
    if d.type == "room_l":
        return "conferenceRoom" if rng.random() < 0.3 else "office"
    if area < 11 or width < 2.9:
        return str(rng.choice(["storage", "WC", "office"], p=[0.4, 0.3, 0.3]))
    if area > 28 and rng.random() < 0.4:
        return "conferenceRoom"
    r = rng.random()
    return "storage" if r < 0.06 else "WC" if r < 0.12 else "office"


def _new_space(d: Draft, sid: int, floor: int, z: float, base_h: float, rng: np.random.Generator,
               counters: dict[str, int]) -> Space:
    t = _room_type(rng, d)
    counters[t] += 1
    h = base_h
    if t == "hallway":
        h = max(2.6, base_h - rng.uniform(0.0, 0.3))
    elif t == "lobby":
        h = min(4.0, base_h + rng.uniform(0.3, 0.9))
    elif t in ("conferenceRoom", "openspace"):
        h = min(4.0, base_h + rng.uniform(0.0, 0.5))
    elif rng.random() < 0.2:
        h = base_h - rng.uniform(0.0, 0.1)
    return Space(sid, f"{t}_{counters[t]}", t, floor, list(d.cells), z0=z, z1=round(z + h, 3), axis=d.axis)


def _ensure_wc(floor_spaces: list[Space], counters: dict[str, int]) -> None:
    """Every floor with five rooms or more has a WC: the smallest office becomes one."""
    rooms = [s for s in floor_spaces if s.type not in CIRCULATION]
    if len(rooms) < 5 or any(s.type == "WC" for s in rooms):
        return
    offices = [s for s in rooms if s.type in ("office", "storage") and len(s.cells) == 1]
    if offices:
        s = min(offices, key=lambda s: ((s.cells[0][2] - s.cells[0][0]) * (s.cells[0][3] - s.cells[0][1]), s.id))
        counters["WC"] += 1
        s.type, s.name = "WC", f"WC_{counters['WC']}"


# -- walls ---------------------------------------------------------------------------------
def _walls(drafts: dict[int, Draft], floor: int, z: float, spaces: list[Space], rng: np.random.Generator,
           ext_t: float, first_id: int, length: float, depth: float) -> list[Wall]:
    """Walls where cells of different spaces meet (or a cell meets the outside), plus partial walls."""
    cells = [(c, sid) for sid, d in drafts.items() for c in d.cells]
    lines: dict[tuple[int, float], dict[str, list]] = defaultdict(lambda: {"lo": [], "hi": []})
    for (x0, y0, x1, y1), sid in cells:
        # horizontal lines (axis 1 = constant y): the cell is above its bottom line, below its top line
        lines[(1, round(y0, 6))]["hi"].append((x0, x1, sid))
        lines[(1, round(y1, 6))]["lo"].append((x0, x1, sid))
        lines[(0, round(x0, 6))]["hi"].append((y0, y1, sid))
        lines[(0, round(x1, 6))]["lo"].append((y0, y1, sid))
    thickness: dict[tuple[int, float], float] = {}
    raw: list[tuple[tuple[float, float], tuple[float, float], int, int, float, str]] = []
    for key in sorted(lines):
        axis, c = key
        lo, hi = lines[key]["lo"], lines[key]["hi"]
        breaks = sorted({v for a, b, _ in lo + hi for v in (a, b)})
        segs: list[list] = []
        for a, b in zip(breaks[:-1], breaks[1:]):
            m = (a + b) / 2
            below = next((s for p, q, s in lo if p < m < q), -1)
            above = next((s for p, q, s in hi if p < m < q), -1)
            if below == above:
                continue
            if segs and segs[-1][1] == a and segs[-1][2:] == [below, above]:
                segs[-1][1] = b
            else:
                segs.append([a, b, below, above])
        for a, b, below, above in segs:
            exterior = below == -1 or above == -1
            if exterior:
                t = ext_t
            else:
                if key not in thickness:
                    thickness[key] = round(float(rng.uniform(0.1, 0.22)), 3)
                t = thickness[key]
            if axis == 1:  # along +x: left (+y) is above
                raw.append(((a, c), (b, c), above, below, t, "exterior" if exterior else "interior"))
            else:  # along +y: left (-x) is the cell whose right side is on the line
                raw.append(((c, a), (c, b), below, above, t, "exterior" if exterior else "interior"))
    for sid, d in drafts.items():
        for p, q in d.partials:
            raw.append((p, q, sid, sid, round(float(rng.uniform(0.1, 0.15)), 3), "partial"))
    walls = []
    for k, (p0, p1, left, right, t, kind) in enumerate(raw):
        zs = [spaces[s].z1 for s in (left, right) if s >= 0]
        walls.append(Wall(first_id + k, floor, (float(p0[0]), float(p0[1])), (float(p1[0]), float(p1[1])),
                          float(t), z, max(zs), left, right, kind))
    shapes.joint_reach(walls)
    return walls


# -- doors ---------------------------------------------------------------------------------
def _door_room(w: Wall, width: float) -> tuple[float, float] | None:
    """The range of door centres along a wall that keeps a door of ``width`` clear of the joints."""
    lo = max(w.ext0, 0.05) + 0.18 + width / 2
    hi = w.length - max(w.ext1, 0.05) - 0.18 - width / 2
    return (lo, hi) if hi >= lo else None


def _doors(rng: np.random.Generator, walls: list[Wall], spaces: list[Space], openings: list[Opening],
           drafts: dict[int, Draft], exterior_door: bool, closed: set[int] = frozenset()) -> None:
    """Doors so that every space of the floor is reachable, plus a few extra between rooms.

    The doors of the spaces in ``closed`` (rooms never scanned) are closed.
    """
    by_pair: dict[tuple[int, int], list[Wall]] = defaultdict(list)
    for w in walls:
        if w.kind == "interior":
            by_pair[tuple(sorted((w.left, w.right)))].append(w)
    circ = {sid for sid in drafts if spaces[sid].type in CIRCULATION}
    parent = {sid: sid for sid in drafts}

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def best_wall(pair, width):
        ws = [w for w in by_pair.get(pair, []) if _door_room(w, width)]
        return max(ws, key=lambda w: w.length) if ws else None

    def add(pair, double=False, leaf=None):
        a, b = pair
        width = rng.uniform(1.5, 1.9) if double else rng.uniform(0.8, 1.0)
        w = best_wall(pair, width)
        if w is None and double:
            double, width = False, rng.uniform(0.8, 1.0)
            w = best_wall(pair, width)
        if w is None:
            return False
        lo, hi = _door_room(w, width)
        c = rng.uniform(lo, hi)
        zmax = min(spaces[s].z1 for s in pair) - w.z0 - 0.25
        h = min(rng.uniform(2.0, 2.2), zmax)
        if leaf is None:
            r = rng.random()
            leaf = "closed" if r < 0.45 else "open" if r < 0.9 else "none"
        if closed and (a in closed or b in closed):
            leaf = "closed"
        # leaves swing into the room, not the hallway
        into = b if a in circ and b not in circ else a if b in circ and a not in circ else pair[rng.integers(2)]
        swing = w.side_of(into)
        o = Opening(len(openings), "door", w.id, round(c - width / 2, 4), round(c + width / 2, 4), w.z0,
                    round(w.z0 + h, 4), leaf=leaf, leaves=2 if double else 1, swing=swing,
                    angle=float(rng.uniform(math.radians(60), math.radians(100))))
        w.openings.append(o)
        openings.append(o)
        parent[find(a)] = find(b)
        return True

    pairs = sorted(by_pair)
    # hallways and lobby join each other through wide doors held open
    for a, b in pairs:
        if a in circ and b in circ:
            add((a, b), double=True, leaf=str(rng.choice(["open", "none"])))
    # every room opens on the circulation it touches (the longest such wall)
    for sid in sorted(drafts):
        if sid in circ:
            continue
        cands = [p for p in pairs if sid in p and (p[0] in circ or p[1] in circ)]
        if cands:
            p = max(cands, key=lambda p: max(w.length for w in by_pair[p]))
            big = spaces[sid].type in ("conferenceRoom", "openspace") and rng.random() < 0.5
            add(p, double=big)
    # whatever is still cut off joins through any neighbour
    for _ in range(len(drafts)):
        roots = {find(s) for s in drafts}
        if len(roots) == 1:
            break
        main = find(min(circ)) if circ else find(min(drafts))
        linked = False
        for p in pairs:
            if (find(p[0]) == main) != (find(p[1]) == main):
                if add(p):
                    linked = True
                    break
        if not linked:
            break
    # a few extra doors between neighbouring rooms
    for p in pairs:
        if p[0] not in circ and p[1] not in circ and find(p[0]) == find(p[1]) and rng.random() < 0.12:
            if not any(o for w in by_pair[p] for o in w.openings):
                add(p)
    if exterior_door:
        lobby = [sid for sid in drafts if spaces[sid].type == "lobby"] or sorted(circ)[:1]
        ext = [w for w in walls if w.kind == "exterior" and lobby and lobby[0] in (w.left, w.right)]
        ext = [w for w in ext if _door_room(w, 1.8)]
        if ext:
            w = max(ext, key=lambda w: w.length)
            lo, hi = _door_room(w, 1.8)
            c = rng.uniform(lo, hi)
            h = min(2.3, spaces[lobby[0]].z1 - w.z0 - 0.3)
            o = Opening(len(openings), "door", w.id, round(c - 0.9, 4), round(c + 0.9, 4), w.z0,
                        round(w.z0 + h, 4), leaf="closed", leaves=2, swing=w.side_of(lobby[0]))
            w.openings.append(o)
            openings.append(o)


def _windows(rng: np.random.Generator, walls: list[Wall], spaces: list[Space], openings: list[Opening],
             style: dict) -> None:
    """Regularly spaced windows on exterior walls (fewer in WCs and storage rooms)."""
    for w in walls:
        if w.kind != "exterior":
            continue
        sid = w.left if w.left >= 0 else w.right
        sp = spaces[sid]
        if sp.type in ("WC", "storage") and rng.random() < 0.5:
            continue
        width = style["window_width"]
        period = width + style["window_gap"]
        lo = w.ext0 + 0.35
        hi = w.length - w.ext1 - 0.35
        taken = [(o.s0 - 0.3, o.s1 + 0.3) for o in w.openings]
        usable = hi - lo
        n = int((usable + style["window_gap"]) // period)
        if n < 1:
            if usable < 0.9:
                continue
            n, width = 1, min(width, usable)
        start = lo + (usable - (n * width + (n - 1) * style["window_gap"])) / 2
        sill = w.z0 + style["sill"]
        head = min(sill + style["window_height"], sp.z1 - 0.3)
        if head - sill < 0.5:
            continue
        for k in range(n):
            s0 = start + k * period
            s1 = s0 + width
            if any(s0 < b and s1 > a for a, b in taken):
                continue
            o = Opening(len(openings), "window", w.id, round(s0, 4), round(s1, 4), round(sill, 4), round(head, 4))
            w.openings.append(o)
            openings.append(o)


# -- parts -----------------------------------------------------------------------------------
def plan_parts(b: Building, part_points: int) -> list[PartSpec]:
    """Cut every space whose estimated point count exceeds ``part_points`` into slabs; one task each."""
    parts: list[PartSpec] = []
    for s in b.spaces:
        est = structure.estimate_points(s, b.density)
        n = max(1, math.ceil(est / max(part_points, 1)))
        fp = s.footprint
        ext = fp.max(0) - fp.min(0)
        axis = int(np.argmax(ext))
        lo, hi = float(fp[:, axis].min()), float(fp[:, axis].max())
        edges = np.linspace(lo, hi, n + 1)
        for k in range(n):
            a = -math.inf if k == 0 else float(edges[k])
            c = math.inf if k == n - 1 else float(edges[k + 1])
            parts.append(PartSpec(len(parts), s.id, k, n, axis, a, c, int(est / n)))
    return parts
