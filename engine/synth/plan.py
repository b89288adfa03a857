"""The plan of a whole building: floors of spaces, walls with doors and windows, and every element.

:func:`plan_building` is deterministic for a seed: each floor's layout, each
space's furniture and each part's scan draw from their own random stream
(:func:`engine.synth.streams.rng_for`), so nothing depends on the order in
which dask runs the tasks.

Steps per floor: a layout of centre-line cells (:mod:`engine.synth.layout`);
spaces with their types and heights (:mod:`engine.synth.rooms`); walls where
cells of different spaces (or the outside) meet, one thickness per wall line
(:mod:`engine.synth.walls`); clear footprints (cells minus wall bodies); doors
chosen so that every space of the floor is reachable from its hallways and
windows on exterior walls (:mod:`engine.synth.openings`); then per space the
structural elements (:mod:`engine.synth.structure`), the furniture
(:mod:`engine.synth.furniture`) and the scan positions
(:mod:`engine.synth.scanners`); last the scan tasks (:mod:`engine.synth.parts`).
"""
from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from shapely.geometry import box

from engine import config
from engine.synth import colours, furniture, shapes, structure
from engine.synth.building import Building, Element, FloorInfo, Frame, Opening, Space, Wall
from engine.synth.hard import plan as hard_plan
from engine.synth.hard.elements import stair_scanners
from engine.synth.hard.hardness import HardContext, Hardness, hard_rng
from engine.synth.layout import Draft, floor_layout
from engine.synth.openings import place_doors, place_windows
from engine.synth.parts import plan_parts
from engine.synth.rooms import ensure_wc, new_space
from engine.synth.scanners import place_scanners
from engine.synth.streams import (
    S_BUILDING,
    S_DOORS,
    S_FLOOR,
    S_FURNITURE,
    S_SPACE,
    S_SUBSAMPLE,
    S_VARIETY,
    S_WINDOWS,
    rng_for,
    style_families,
    style_name,
)
from engine.synth.walls import grid_walls, thickness_draw
from tiles.errors import UserError

#: Average floor area per space, used to turn ``rooms`` into an area.
AREA_PER_SPACE = 31.0
MIN_AREA_PER_FLOOR = 40.0


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
                  part_points: int | None = None, hardness=None, styles: str = "classic") -> Building:
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
    styles
        ``"classic"`` (the training buildings' styles) or ``"varied"``: each element drawn from its style family
        (boards: with a pen tray or bare, 1-4 cm; rooms: saturated walls, dark rooms, scan noise 1-10 mm, a
        density factor x0.25-x4), from streams of its own: the plan is the classic building's, and so is the
        furniture of every room without a new style; ``"subsampled"``: each room's scan voxel-subsampled on a
        1-5 cm grid; ``"windows"``: each exterior wall's window type (punched, ribbon, full-height, tall; with or
        without mullions and sill); ``"doors"``: each door's type (classic, flush, glazed, sliding);
        ``"furniture"``: each chair's shape (five-star, cantilever, armchair, stool, wide); or a
        comma-separated combination (:data:`engine.synth.streams.FAMILIES`).
    """
    try:
        families = style_families(styles)
    except ValueError as e:
        raise UserError(None, str(e)) from None
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

    pl = _start_plan(int(seed), h, floors, area_m2, rooms, area_given)
    for family, key, stream in (("varied", "variety", S_VARIETY), ("subsampled", "subsample", S_SUBSAMPLE),
                                ("windows", "windows", S_WINDOWS), ("doors", "doors", S_DOORS),
                                ("furniture", "furniture", S_FURNITURE)):
        if family in families:
            pl.style[key] = int(rng_for(int(seed), stream).integers(2 ** 31))
    z = 0.0
    for f in range(floors):
        z = _plan_floor(pl, f, z, top=(f == floors - 1))
    _link_walls(pl.spaces, pl.walls)
    _add_elements(pl, hard)
    _number_elements(pl.spaces, pl.openings)
    params = {"seed": int(seed), "area_m2": area_m2, "rooms": rooms, "floors": floors, "density": density,
              "part_points": part_points, "generator": "engine.synth"}
    if h:
        params["hardness"] = h.to_dict()
    if families:
        params["styles"] = style_name(families)
    b = Building(int(seed), frame, density, pl.spaces, pl.walls, pl.openings, pl.floor_infos, params=params)
    b.parts = plan_parts(b, part_points)
    return b


@dataclass
class _Plan:
    """What the floors of a building are planned from (the building's draws) and what they add to."""

    seed: int
    h: Hardness
    style: dict
    ext_t: float
    ext_hard: float | None
    layouts: list
    geo: Any
    spaces: list[Space] = field(default_factory=list)
    walls: list[Wall] = field(default_factory=list)
    openings: list[Opening] = field(default_factory=list)
    floor_infos: list[FloorInfo] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=lambda: defaultdict(int))


def _start_plan(seed: int, h: Hardness, floors: int, area_m2: float, rooms: int | None, area_given: bool) -> _Plan:
    """The building's own draws: style, exterior wall thickness, the floors' layouts and the geometric difficulties."""
    brng = rng_for(seed, S_BUILDING)
    style = colours.building_style(brng)
    ext_t = round(brng.uniform(0.25, 0.35), 3)
    layouts = _floor_layouts(seed, floors, area_m2, rooms, area_given)
    if h.on("open_plan"):
        for f, lay in enumerate(layouts):
            hard_plan.large_open_space(hard_rng(seed, "open_plan", 0, f), lay, h.level("open_plan"))
    geo = hard_plan.Geometry.plan(int(seed), h, layouts, area_m2 / floors) if h.geometric else None
    ext_hard = None
    if h.on("walls") and hard_rng(seed, "walls", 1000).random() < 0.5 * h.level("walls"):
        ext_hard = round(float(hard_rng(seed, "walls", 1001).uniform(0.4, 0.7)), 3)
    return _Plan(seed, h, style, ext_t, ext_hard, layouts, geo)


def _plan_floor(pl: _Plan, f: int, z: float, top: bool) -> float:
    """Spaces, walls, footprints, doors and windows of floor ``f`` at height ``z``; returns the next floor's height."""
    seed, h, spaces = pl.seed, pl.h, pl.spaces
    frng = rng_for(seed, S_FLOOR, f, 1000)
    base_h = round(frng.uniform(2.7, 3.3), 3)
    drafts = _floor_spaces(pl, f, z, base_h, frng)
    closed: set[int] = set()
    if h.on("unscanned"):
        closed = hard_plan.choose_unscanned(hard_rng(seed, "unscanned", f), [spaces[sid] for sid in drafts],
                                            {sid: d.area for sid, d in drafts.items()}, h.level("unscanned"))
    floor_walls, polys = _floor_walls(pl, f, z, frng, drafts)
    pl.walls.extend(floor_walls)
    shapes.clear_footprints(polys, floor_walls, spaces)
    place_doors(frng, floor_walls, spaces, pl.openings, drafts, exterior_door=(f == 0), closed=closed)
    place_windows(frng, floor_walls, spaces, pl.openings, pl.style)
    if h.on("hidden_walls"):
        hard_plan.line_walls(hard_rng(seed, "hidden_walls", f), floor_walls, spaces, h.level("hidden_walls"))
    return _stack_floor(pl, f, z, frng, drafts, floor_walls, top)


def _floor_spaces(pl: _Plan, f: int, z: float, base_h: float, frng: np.random.Generator) -> dict[int, Draft]:
    """The spaces of floor ``f`` (appended to the plan's); returns their drafts by space id."""
    spaces, h = pl.spaces, pl.h
    lay = pl.layouts[f]
    first = len(spaces)
    fdrafts = pl.geo.floor(f, lay) if pl.geo is not None else lay.drafts
    for d in fdrafts:
        spaces.append(new_space(d, len(spaces), f, z, base_h, frng, pl.counters))
        if h.on("bottlenecks") and spaces[-1].type == "hallway":
            lift = hard_rng(pl.seed, "bottlenecks", 0, spaces[-1].id).uniform(0.3, 0.8) * h.level("bottlenecks")
            spaces[-1].z1 = round(z + min(4.2, base_h + lift), 3)
    ensure_wc(spaces[first:], pl.counters)
    return {first + i: d for i, d in enumerate(fdrafts)}


def _floor_walls(pl: _Plan, f: int, z: float, frng: np.random.Generator,
                 drafts: dict[int, Draft]) -> tuple[list[Wall], dict[int, Any]]:
    """The walls of floor ``f`` (with their thin, thick and glass difficulties) and each space's polygon."""
    seed, h, spaces = pl.seed, pl.h, pl.spaces
    if pl.geo is not None:
        polys = {sid: d.poly for sid, d in drafts.items()}
        floor_walls = shapes.walls_from_polygons(polys, {sid: d.partials for sid, d in drafts.items()
                                                         if d.partials}, f, z, spaces, thickness_draw(frng),
                                                 pl.ext_t, len(pl.walls))
    else:
        lay0 = pl.layouts[0]
        floor_walls = grid_walls(drafts, f, z, spaces, frng, pl.ext_t, len(pl.walls), lay0.length, lay0.depth)
    changed = False
    if h.on("walls"):
        changed |= hard_plan.thin_and_thick(hard_rng(seed, "walls", f), floor_walls, h.level("walls"), pl.ext_hard)
    if h.on("glass"):
        changed |= hard_plan.glass_walls(hard_rng(seed, "glass", f), floor_walls, spaces, h.level("glass"))
    if changed:
        shapes.joint_reach(floor_walls)
    if pl.geo is None:  # Manhattan plan: each space's polygon is the union of its cells
        polys = {sid: shapely.union_all([box(*c) for c in d.cells]) for sid, d in drafts.items()}
    return floor_walls, polys


def _stack_floor(pl: _Plan, f: int, z: float, frng: np.random.Generator, drafts: dict[int, Draft],
                 floor_walls: list[Wall], top: bool) -> float:
    """The floor's ceiling void and slab, its stair towers' heights and its :class:`FloorInfo`; the next floor's z."""
    spaces = pl.spaces
    ceiling_max = max(spaces[i].z1 for i in drafts if spaces[i].type != "stairs") - z
    plenum = frng.uniform(0.1, 0.6)
    slab = frng.uniform(0.2, 0.4)
    nxt = round(z + ceiling_max + plenum + slab, 3)
    for sid in drafts:
        if spaces[sid].type == "stairs":
            _stair_heights(spaces[sid], floor_walls, spaces, nxt, top, f, slab)
    pl.floor_infos.append(FloorInfo(f, z, z + ceiling_max, (nxt - slab, nxt if not top else nxt - slab)))
    return nxt


def _link_walls(spaces: list[Space], walls: list[Wall]) -> None:
    """Each space's walls, doors and windows (sorted ids)."""
    for w in walls:
        for o in w.openings:
            for s in (w.left, w.right):
                if s >= 0:
                    (spaces[s].doors if o.kind == "door" else spaces[s].windows).append(o.id)
        for s in {w.left, w.right} - {-1}:
            spaces[s].walls.append(w.id)
    for s in spaces:
        s.doors, s.windows = sorted(set(s.doors)), sorted(set(s.windows))


def _add_elements(pl: _Plan, hard: HardContext | None) -> None:
    """Structure, furniture and scan positions of every space, each from its own random stream."""
    seed, spaces, walls, openings, style = pl.seed, pl.spaces, pl.walls, pl.openings, pl.style
    for s in spaces:
        srng = rng_for(seed, S_SPACE, s.id)
        colours.space_colours(srng, s, style)
        shapes.in_local_frame(s, walls, lambda lw: structure.add_structure(srng, s, lw, openings, style, hard=hard))
        shapes.in_local_frame(s, walls, lambda lw: furniture.furnish(srng, s, lw, openings, style, hard=hard))
        if s.scanned and s.stairs is not None:
            shapes.in_local_frame(s, walls, lambda lw: stair_scanners(s, hard_rng(seed, "stairs", 1, s.id)))
        elif s.scanned:
            shapes.in_local_frame(s, walls, lambda lw: place_scanners(srng, s))
        else:
            s.scanners = np.zeros((0, 3))
    if hard is not None:
        _hard_spaces(hard, spaces, walls)


def _number_elements(spaces: list[Space], openings: list[Opening]) -> None:
    """Element ids in space order, boxes fitted, and each door and window opening's elements."""
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
