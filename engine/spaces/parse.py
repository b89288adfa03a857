"""Space parsing of a whole building (paper section 3): the stage that turns a tile store into spaces.

Steps, each a batch of dask tasks over the tiles (nothing loads the building
into one process; the driver only sums small per-tile results):

1. one pass: per-tile orientation evidence (:mod:`engine.spaces.alignment`) and the
   z histogram; small tasks refine the yaw from the evidence -> the aligned frame;
2. storeys from the z histogram (:func:`engine.spaces.slicing.find_storeys`);
3. recursive slicing along u and v (:mod:`engine.spaces.slicing`): one pass per round,
   one task per box searched; the upper band above ``upper_band`` metres over
   each storey's floor gets its own histograms;
4. merging (:mod:`engine.spaces.merging`): one pass for all shared faces, one task per
   face, then agglomeration of the cells through the faces without a divider
   (most open pair of groups first; a leaky face does not chain two rooms) and
   absorption of weak groups;
5. refinement (:mod:`engine.spaces.refine`): every space of at least ``refine_min_area``
   m² is parsed again on its own points, in its own frame(s), one task per
   space, with ridge dividers besides the voids (:mod:`engine.spaces.ridges`: walls
   seen as one dense surface); when that splits it, its pieces replace it (a
   wing at an angle, a large cell never cut, rooms glued through a wall with
   no void).  Building faces beside a refined space are cut where the new
   space beyond changes, and the pieces rejoin neighbours beyond the refined
   space through open faces (:mod:`engine.spaces.rejoin`).  A face between a side
   with a ceiling in the storey and a side without one (a stair shaft beside
   its lobby) is divided there too, and lines where the ceiling changes
   height (a glazed partition) cut and divide like ridges (:mod:`engine.spaces.ceilings`);
6. one pass writing ``cell_id`` and ``space_id`` (int32, -1 none) in every tile
   (a refined space's points located in its new cells) and collecting
   per-space counts, z ranges and tiles.

The document ``meta/spaces`` (:meth:`SpaceParse.to_doc`), which later stages
rely on::

    {"version": 1,
     "frame": {"yaw", "yaw_deg", "origin": [x, y, z]},
         # aligned = R(-yaw) (world - origin): u = c*dx + s*dy, v = -s*dx + c*dy, z' = z - origin_z
         # world:   x = origin_x + c*u - s*v, y = origin_y + s*u + c*v  (c, s = cos, sin of yaw)
     "grid": {"bin_width", "z_bin"},          # bins of the aligned frame (metres)
     "floors": [{"id", "z_range": [z0, z1] (world), "point_count"}],
     "cells": [{"id", "floor", "box": [u0, v0, u1, v1] (aligned metres), "point_count", "space",
                "yaw"}],  # yaw: null, or the frame (radians, same origin) of a refined space's cell;
                          # a refined space's former cells stay with "space": -1 and no points
     "dividers": [{"axis": "u"|"v"|"z", "floor" (-1 for slabs), "position" (aligned metres along axis;
                   for "z" world z), "width", "extent": [a, b] (along the other horizontal axis),
                   "score", "kind": "peak-gap-peak"|"empty"|"ridge", "level", "contrast", "void_ratio",
                   "yaw" (only in a refined space's own frame)}],
     "spaces": [{"id", "floor", "cells": [ids], "footprint": GeoJSON Polygon/MultiPolygon (world x, y),
                 "area_m2", "z_range": [z0, z1] (world), "point_count", "tiles": [names],
                 "neighbours": [{"space", "faces": [{"axis", "position", "extent": [a, b], "z_range",
                                 "segment": [[x0, y0], [x1, y1]] (world), "divider": bool,
                                 "divider_kind", "score", "yaw"}]}]}],  # yaw: as the cells'
                 # divider_kind: a divider's kind, or "ridge" / "ceiling" (engine.spaces.ridges, engine.spaces.ceilings)
                 # a refined space's footprint is its new cells' union clipped to the space it came from
     "unassigned_points", "point_count",
     "stats": {"passes": [{"pass", "searched", "dividers", "boxes", "tiles"}], "cells", "edges",
               "edges_divided", "absorbed", "dropped", "merges_refused", "refine_searched",
               "refined": [{"space", "spaces", "yaw_deg": [per part]}], "seconds": {step: seconds}},
     "params": {...}}

A face is a piece of a shared face between two cells of the two spaces, along
``axis`` (the face is normal to it) at ``position``; ``extent`` runs along the
other horizontal axis; contiguous pieces with the same divider status are
joined.  These are the *connection areas* of paper section 4.2: the space
update removes a neighbour edge only where a detected wall lies in one, and
doors are sought in the faces without divider.  The per-tile orientation
evidence is in ``meta/alignment`` (see :class:`engine.spaces.alignment.Alignment`).
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from engine import config
from engine.spaces.alignment import AlignmentSettings, Frame, estimate_alignment, tile_evidence
from engine.spaces.ceilings import CeilingSettings
from engine.spaces.dividers import DividerSettings, vertical_params
from engine.spaces.histograms import BoxIndex, Grid, share, tile_extents, tiles_by_size, tiles_touching, z_histogram
from engine.spaces.merging import Edge, MergeRules, merge, neighbour_edges, test_edges
from engine.spaces.refine import Refinement, clipped_footprint, face_side_space, refine_spaces, relabel
from engine.spaces.rejoin import rejoin_pieces
from engine.spaces.ridges import RidgeSettings
from engine.spaces.slicing import Box, FoundDivider, find_storeys, floor_levels, slice_storeys
from tiles.schema import Dimension
from tiles.store import TileStore
from tiles.tasks import run_tasks

if TYPE_CHECKING:
    from distributed import Client

DOC = "spaces"
VERSION = 1


# -- parameters -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class SpaceSettings:
    """All parameters of space parsing, physical (metres) or scale-free; see ``engine/spaces/spaces.yaml``."""

    bin_width: float = 0.01
    z_bin: float = 0.02
    walls: DividerSettings = field(default_factory=DividerSettings)
    slabs: DividerSettings = field(default_factory=vertical_params)
    alignment: AlignmentSettings = field(default_factory=AlignmentSettings)
    yaw: float | None = None  # degrees; None: estimate
    max_levels: int = 8
    #: Slicing accepts walls that span only part of a box: their void, in the upper band, may hold up to
    #: this fraction of the room level (the rest of the box's cross-section); merging then decides each
    #: shared face with the strict ``walls.max_void_ratio``.
    slicing_void_ratio: float = 0.7
    slicing_void_ratio_full: float = 0.85
    min_storey_height: float = 2.0
    upper_band: float = 2.2  # m above a storey's floor: doors end below, walls are solid above
    merge_window: float = 1.6
    min_face: float = 0.3
    min_space_area: float = 1.0
    min_space_width: float = 0.5
    min_relative_density: float = 0.02
    #: Merging joins two groups of cells when the faces without a divider between them are at least this
    #: fraction of the smaller group's boundary (see :func:`engine.spaces.merging.agglomerate`) ...
    min_open_ratio: float = 0.05
    #: ... and a face to a cell with fewer points per m² than this fraction of the median cell's does not count.
    min_scanned_density: float = 0.2
    #: Spaces of at least this many m² are parsed again on their own points in their own frame
    #: (:mod:`engine.spaces.refine`; 0: never) ...
    refine_min_area: float = 80.0
    #: ... whose yaw, when within this many degrees of the building's, is the building's.
    refine_snap_deg: float = 2.0
    #: A refined space whose walls follow a second orientation at least ``refine_separation_deg`` from the
    #: first, with at least ``refine_min_second`` of its weight, is split into the regions of the two
    #: (votes summed over ``refine_block`` m squares, smoothed over ``refine_smooth`` m), each parsed in
    #: its own frame.
    refine_separation_deg: float = 5.0
    refine_min_second: float = 0.5
    refine_block: float = 0.5
    refine_smooth: float = 1.5
    #: Ridge dividers (walls seen as one dense surface) in the refinement: :mod:`engine.spaces.ridges`.
    ridges: RidgeSettings = field(default_factory=RidgeSettings)
    #: Refined pieces join their neighbours beyond the refined space through open faces
    #: (:mod:`engine.spaces.rejoin`).
    rejoin: bool = True
    #: In the refinement, a face without a divider between a side with a ceiling in the storey and a side
    #: without one (a stair shaft beside its lobby) is divided, and lines where the ceiling changes height cut
    #: and divide like ridge lines: :mod:`engine.spaces.ceilings`.
    ceilings: CeilingSettings = field(default_factory=CeilingSettings)

    def __post_init__(self) -> None:
        object.__setattr__(self, "walls", dataclasses.replace(self.walls, bin_width=self.bin_width))
        object.__setattr__(self, "slabs", dataclasses.replace(self.slabs, bin_width=self.z_bin))

    @property
    def slicing_walls(self) -> DividerSettings:
        """The wall search of slicing: permissive void ratios (see ``slicing_void_ratio``)."""
        return dataclasses.replace(self.walls, max_void_ratio=self.slicing_void_ratio,
                                   max_void_ratio_full=self.slicing_void_ratio_full)

    @property
    def rules(self) -> MergeRules:
        return MergeRules(self.min_space_area, self.min_space_width, self.min_relative_density,
                          self.min_open_ratio, self.min_scanned_density)

    @classmethod
    def from_config(cls, **overrides: Any) -> SpaceSettings:
        """The parameters under ``buildingparser.spaces`` in dask.config, with overrides."""
        kw = config.settings_fields(cls, "spaces")  # walls, slabs, alignment, ridges, ceilings: their sections
        kw.update(overrides)
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["walls"], d["slabs"] = self.walls.to_dict(), self.slabs.to_dict()
        d["alignment"] = self.alignment.to_dict()
        d["ridges"] = self.ridges.to_dict()
        d["ceilings"] = self.ceilings.to_dict()
        return d


# -- the document's mirror ---------------------------------------------------------------------------

@dataclass
class Floor:
    id: int
    z_range: list[float]
    point_count: int = 0


@dataclass
class Cell:
    id: int
    floor: int
    box: list[float]  # [u0, v0, u1, v1] aligned metres
    point_count: int
    space: int
    yaw: float | None = None  # the box's frame when not the building's (a refined space's cell; same origin)


@dataclass
class Face:
    axis: str
    position: float
    extent: list[float]
    z_range: list[float]
    segment: list[list[float]]
    divider: bool
    divider_kind: str | None = None
    score: float | None = None
    yaw: float | None = None  # the frame of axis/position/extent when not the building's (same origin)


@dataclass
class Neighbour:
    space: int
    faces: list[Face]

    @property
    def length(self) -> float:
        return float(sum(f.extent[1] - f.extent[0] for f in self.faces))


@dataclass
class Space:
    id: int
    floor: int
    cells: list[int]
    footprint: dict[str, Any]
    area_m2: float
    z_range: list[float]
    point_count: int
    tiles: list[str]
    neighbours: list[Neighbour]


@dataclass
class SpaceParse:
    """The result of space parsing: the mirror of the ``meta/spaces`` document."""

    frame: Frame
    bin_width: float
    z_bin: float
    floors: list[Floor]
    cells: list[Cell]
    dividers: list[FoundDivider]
    spaces: list[Space]
    point_count: int = 0
    unassigned_points: int = 0
    stats: dict[str, Any] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)

    def space(self, space_id: int) -> Space:
        return next(s for s in self.spaces if s.id == space_id)

    def to_doc(self) -> dict[str, Any]:
        return _jsonable({
            "version": VERSION, "frame": self.frame.to_json(),
            "grid": {"bin_width": self.bin_width, "z_bin": self.z_bin},
            "floors": [dataclasses.asdict(f) for f in self.floors],
            "cells": [dataclasses.asdict(c) for c in self.cells],
            "dividers": [d.to_json() for d in self.dividers],
            "spaces": [dataclasses.asdict(s) for s in self.spaces],
            "point_count": self.point_count, "unassigned_points": self.unassigned_points,
            "stats": self.stats, "params": self.params})

    @classmethod
    def from_doc(cls, d: dict[str, Any]) -> SpaceParse:
        spaces = []
        for s in d["spaces"]:
            nbs = [Neighbour(n["space"], [Face(**f) for f in n["faces"]]) for n in s["neighbours"]]
            spaces.append(Space(**{**s, "neighbours": nbs}))
        return cls(frame=Frame.from_json(d["frame"]), bin_width=d["grid"]["bin_width"], z_bin=d["grid"]["z_bin"],
                   floors=[Floor(**f) for f in d["floors"]], cells=[Cell(**c) for c in d["cells"]],
                   dividers=[FoundDivider.from_json(x) for x in d["dividers"]], spaces=spaces,
                   point_count=d.get("point_count", 0), unassigned_points=d.get("unassigned_points", 0),
                   stats=d.get("stats", {}), params=d.get("params", {}))

    @classmethod
    def load(cls, store: TileStore) -> SpaceParse:
        """The parse stored in a tile store's ``meta/spaces``."""
        doc = store.doc(DOC)
        if doc is None:
            from tiles.errors import UserError

            raise UserError(store.url, "no space parsing in this tile store: run 'buildingparser spaces' first")
        return cls.from_doc(doc)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    return x


# -- tasks ---------------------------------------------------------------------------------------------

def _first_pass(tile: str, store, params: AlignmentSettings, grid: Grid, z_lo: int, z_n: int) -> dict[str, Any]:
    """Orientation evidence and z histogram of one tile (one read of its coordinates)."""
    m = store.meta
    raw = store.read(tile, ("x", "y", "z"))
    xy = np.empty((len(raw["x"]), 2))
    for i, a in enumerate("xy"):
        np.multiply(raw[a], m.scale[i], out=xy[:, i], casting="unsafe")
        xy[:, i] += m.offset[i] - m.origin[i]
    bz = grid.tile_z_bins(raw["z"], m)
    return {"evidence": tile_evidence(xy, params), "z": z_histogram(bz, z_lo, z_n)}


def _label_tile(tile: str, store, grid: Grid, index: BoxIndex, cell_space: np.ndarray,
                refined: list[tuple[Refinement, list[tuple[Grid, BoxIndex, int]]]], owner: np.ndarray
                ) -> dict[str, Any]:
    """Write ``cell_id`` and ``space_id`` of one tile; its cells' and spaces' point counts and z ranges (sparse).

    Points of a refined space are located in its refinement's cells (:func:`engine.spaces.refine.relabel`).
    """
    m = store.meta
    raw = store.read(tile, ("x", "y", "z"))
    bu, bv, bz = grid.raw_bins(raw, grid.raw_affine(m))
    cell = index.locate(bu, bv, bz)
    if refined:
        cell = relabel(cell, raw, m, refined, owner)
    space = np.append(cell_space, -1)[cell]  # cell -1 -> space -1
    store.write_array(tile, "cell_id", cell.astype(np.int32))
    store.write_array(tile, "space_id", space.astype(np.int32))
    inside = cell >= 0
    per = np.bincount(cell[inside], minlength=len(cell_space))
    cells = np.flatnonzero(per)
    counts = per[cells]
    # z range per cell from the raw integers (monotonic in z); the driver reduces them per space
    big = np.iinfo(np.int64).max
    zmin_all, zmax_all = np.full(len(cell_space), big), np.full(len(cell_space), -big)
    zr = raw["z"][inside].astype(np.int64)
    np.minimum.at(zmin_all, cell[inside], zr)
    np.maximum.at(zmax_all, cell[inside], zr)
    zmin, zmax = zmin_all[cells], zmax_all[cells]
    return {"cells": cells, "counts": counts, "zmin": zmin * m.scale[2] + m.offset[2],
            "zmax": zmax * m.scale[2] + m.offset[2], "unassigned": int((space < 0).sum())}


# -- the stage ---------------------------------------------------------------------------------------------

def _refine(store, grid: Grid, p: SpaceSettings, floors: np.ndarray, band_z: np.ndarray, cells: list[Box],
            labels: np.ndarray, index: BoxIndex, client) -> list[Refinement]:
    """Every space of at least ``refine_min_area`` m² parsed again in its own frame (one task each)."""
    if p.refine_min_area <= 0 or not len(cells) or labels.max() < 0:
        return []
    bw = p.bin_width
    area = np.array([(c.u1 - c.u0) * (c.v1 - c.v0) for c in cells], dtype=np.float64) * bw * bw
    ok = labels >= 0
    space_area = np.bincount(labels[ok], weights=area[ok], minlength=int(labels.max()) + 1)
    extents = tile_extents(store, grid)
    names = [t.name for t in store.tiles]
    items = []
    for sp in np.flatnonzero(space_area >= p.refine_min_area).tolist():
        members = np.flatnonzero(labels == sp)
        touch = tiles_touching(extents, floors, np.array([cells[i].row() for i in members]))
        items.append({"space": int(sp), "floor": int(cells[members[0]].floor), "cells": members,
                      "tiles": [names[i] for i in np.flatnonzero(touch)]})
    if not items:
        return []
    return refine_spaces(items, store, index, grid, p, floors, band_z, client)  # largest first, parallel reads


@dataclass
class _RefinedPlan:
    """The building's cells and edges with the refinements' appended, and the spaces renumbered.

    A refined space's own cells keep their ids but get no space (-1); its new
    cells follow the building's (``firsts[k]``: the first of refinement ``k``)
    and their spaces replace it, numbered in its place.  ``sides[e]`` is the
    space on each side of edge ``e``: a building edge next to a refined space
    gets the new space found on its side of the face; ``edge_yaw[e]`` the frame
    of a refinement's edge (None: the building's).
    """

    cells: list[Box]
    edges: list[Edge]
    labels: np.ndarray
    owner: np.ndarray
    refinements: list[Refinement]
    firsts: list[list[int]]
    cell_yaw: list[float | None]
    edge_yaw: list[float | None]
    sides: np.ndarray
    sub_of: dict[int, tuple[int, float]]
    clip: dict[int, list[int]]
    dividers: list[FoundDivider]
    n_spaces: int
    #: The pieces of the building faces between two refined spaces that were cut where the new space on a
    #: side changes (indices into ``edges``): each still carries the divider found on the whole face and is
    #: tested again on its own stretch.  Beside a space that was not refined, a piece keeps the whole face's
    #: divider (a piece's own stretch misled the test there: an outer wall beside unscanned ground that a
    #: refined piece had stretched over, h400-2storeys-yaw-20 0.983 -> 0.943).
    pieces: list[int] = field(default_factory=list)
    #: After :meth:`regroup`: new space -> the spaces (before regrouping) it joins, when more than one,
    #: and each cell's space before regrouping.
    joined: dict[int, list[int]] = field(default_factory=dict)
    before: np.ndarray | None = None
    sub_before: dict[int, tuple[int, float]] = field(default_factory=dict)

    def regroup(self, group: np.ndarray) -> None:
        """Join spaces: ``group[s]`` is the space ``s`` joins (:func:`engine.spaces.rejoin.rejoin_pieces`); renumbered."""
        group = np.asarray(group, dtype=np.int64)
        if np.array_equal(group, np.arange(self.n_spaces)):
            return
        ids = np.unique(group)
        new_of = np.searchsorted(ids, group)  # old space -> new space
        remap = np.append(new_of, -1)  # -1 stays -1
        self.before = self.labels.copy()
        self.sub_before = dict(self.sub_of)
        self.labels = remap[self.labels]
        self.sides = remap[self.sides]
        members: dict[int, list[int]] = {}
        for old, new in enumerate(new_of.tolist()):
            members.setdefault(new, []).append(old)
        self.joined = {new: olds for new, olds in members.items() if len(olds) > 1}
        self.sub_of = {int(new_of[old]): v for old, v in self.sub_before.items()
                       if int(new_of[old]) not in self.joined}
        self.n_spaces = len(ids)

    @classmethod
    def build(cls, cells: list[Box], edges: list[Edge], labels: np.ndarray, refs: list[Refinement],
              frame: Frame | None = None, bin_width: float = 0.01) -> _RefinedPlan:
        kept = [r for r in refs if r.n_spaces >= 2]
        ref_of = {r.space: k for k, r in enumerate(kept)}
        n_old = int(labels.max()) + 1 if len(labels) and labels.max() >= 0 else 0
        new_id = np.full(n_old + 1, -1, dtype=np.int64)  # old space -> new (-1: refined or none)
        base: dict[int, int] = {}
        nxt = 0
        for sp in range(n_old):
            if sp in ref_of:
                base[sp] = nxt
                nxt += kept[ref_of[sp]].n_spaces
            else:
                new_id[sp] = nxt
                nxt += 1
        old = np.asarray(labels, dtype=np.int64)
        lab = [new_id[old]]  # old -1 -> new_id[-1] = -1
        owner = np.full(len(cells) + 1, -1, dtype=np.int64)
        for k, r in enumerate(kept):
            owner[1:][old == r.space] = k
        all_cells = list(cells)
        firsts, sub_of, clip, dividers = [], {}, {}, []
        origin = frame.origin if frame is not None else (0.0, 0.0, 0.0)
        # building edges: the space on each side (a refined side: the new space at the face).  A face beside
        # a refined space is sampled every face-step bins along it and cut where the new space on either side
        # changes: one long building face may border several of the refinement's spaces (a hallway's end and
        # a room), and each piece must connect the right pair.
        def side(e: Edge, j: int, lo: int, at: float) -> int:
            step = -2 if j == 0 else 2  # a lies below the face, b above
            pt = [e.position + step, at] if e.axis == 0 else [at, e.position + step]
            world = frame.to_world(np.asarray(pt, dtype=np.float64) * bin_width)
            got = face_side_space(kept[ref_of[lo]], world, origin, bin_width)
            return base[lo] + got if got >= 0 else -1

        face_step = max(1, int(round(0.25 / bin_width)))
        all_edges, rows, pieces = [], [], []
        for e in edges:
            la, lb = int(old[e.a]), int(old[e.b])
            if (la == lb and la in ref_of) or (la not in ref_of and lb not in ref_of):
                # inside a refined space (its refinement has its own faces), or away from every refinement
                inside = la == lb and la in ref_of
                all_edges.append(e)
                rows.append([-1 if inside or la < 0 else new_id[la], -1 if inside or lb < 0 else new_id[lb]])
                continue
            o0, o1 = e.overlap
            marks = np.unique(np.r_[np.arange(o0, o1, face_step), o1 - 1]).astype(np.float64) + 0.5
            pairs = [tuple(-1 if lo < 0 else (new_id[lo] if lo not in ref_of else side(e, j, lo, t))
                           for j, lo in enumerate((la, lb))) for t in marks]
            start, first = o0, len(all_edges)
            for k in range(1, len(marks) + 1):
                if k == len(marks) or pairs[k] != pairs[k - 1]:
                    stop = o1 if k == len(marks) else int(0.5 * (marks[k - 1] + marks[k]))
                    if stop > start:
                        all_edges.append(dataclasses.replace(e, overlap=(start, stop)))
                        rows.append(list(pairs[k - 1]))
                    start = stop
            if len(all_edges) - first > 1 and la in ref_of and lb in ref_of:
                pieces += range(first, len(all_edges))
        sides = np.array(rows, dtype=np.int64).reshape(-1, 2)
        cell_yaw: list[float | None] = [None] * len(cells)
        edge_yaw: list[float | None] = [None] * len(all_edges)
        for k, r in enumerate(kept):
            firsts.append([])
            at = base[r.space]
            for pt in r.parts:
                first = len(all_cells)
                firsts[-1].append(first)
                all_cells += pt.cells
                cell_yaw += [None if frame is not None and pt.yaw == frame.yaw else pt.yaw] * len(pt.cells)
                sl = np.asarray(pt.labels, dtype=np.int64)
                sub_sides = np.where(sl >= 0, sl + at, -1)
                lab.append(sub_sides)
                rows = []
                for e in pt.edges:
                    all_edges.append(dataclasses.replace(e, a=e.a + first, b=e.b + first))
                    rows.append([sub_sides[e.a], sub_sides[e.b]])
                edge_yaw += [None if frame is not None and pt.yaw == frame.yaw else pt.yaw] * len(pt.edges)
                sides = np.vstack([sides, np.array(rows, dtype=np.int64).reshape(-1, 2)])
                for j in range(pt.n_spaces):
                    sub_of[at + j] = (k, pt.yaw)
                at += pt.n_spaces
                dividers += pt.dividers
            clip[k] = np.flatnonzero(old == r.space).tolist()
        return cls(all_cells, all_edges, np.concatenate(lab) if lab else np.zeros(0, np.int64), owner, kept,
                   firsts, cell_yaw, edge_yaw, sides, sub_of, clip, dividers, nxt, pieces=pieces)


def _initial_boxes(store, grid: Grid, floors: list[tuple[int, int]]) -> list[Box]:
    """One box per storey covering every tile's bounds (rotated corners), in bins."""
    o = np.asarray(store.meta.origin)
    corners = []
    for t in store.tiles:
        x0, y0, _, x1, y1, _ = t.bounds
        corners += [[x0, y0, 0], [x0, y1, 0], [x1, y0, 0], [x1, y1, 0]]
    a = grid.aligned(np.asarray(corners, dtype=np.float64) - o)
    u0 = int(math.floor(a[:, 0].min() / grid.bin_width)) - 1
    u1 = int(math.floor(a[:, 0].max() / grid.bin_width)) + 2
    v0 = int(math.floor(a[:, 1].min() / grid.bin_width)) - 1
    v1 = int(math.floor(a[:, 1].max() / grid.bin_width)) + 2
    return [Box(f, u0, u1, v0, v1) for f in range(len(floors))]


def parse_spaces(store: TileStore, *, client: Client | None = None, params: SpaceSettings | None = None
                 ) -> SpaceParse:
    """Parse a tile store into spaces; writes ``cell_id``/``space_id`` in every tile and ``meta/spaces``.

    Parameters
    ----------
    store
        A :class:`tiles.store.TileStore`.
    client
        A ``distributed.Client`` (None: tasks run here, one after another).
    params
        Parameters; default: :meth:`SpaceSettings.from_config` (``buildingparser.spaces.*``).
    """
    p = params or SpaceSettings.from_config()
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    tiles = tiles_by_size(store)  # largest first (better balance); results kept in this order
    meta = store.meta
    origin = tuple(float(v) for v in meta.origin)
    z_lo = int(math.floor((meta.bounds[2] - origin[2]) / p.z_bin)) - 1
    z_n = int(math.floor((meta.bounds[5] - origin[2]) / p.z_bin)) + 2 - z_lo
    zgrid = Grid.for_store(store, Frame(0.0, origin), p.bin_width, p.z_bin)  # z bins do not depend on the yaw
    # the wall-pixel samples kept for the yaw refinement: at most 2 M over the whole building
    al = dataclasses.replace(p.alignment, max_wall_pixels=max(
        500, min(p.alignment.max_wall_pixels, 2_000_000 // max(len(tiles), 1))))
    first = run_tasks(_first_pass, tiles, client=client, label="spaces: evidence + z histogram", keys=tiles,
                      extra_args=(store, al, zgrid, z_lo, z_n))
    z_hist = np.sum([r["z"] for r in first], axis=0)
    seconds["first_pass"] = time.perf_counter() - t0

    t = time.perf_counter()
    if p.yaw is None:
        by_name = dict(zip(tiles, first))
        alignment = estimate_alignment(store, client=client, params=al,
                                       evidence=[by_name[t.name]["evidence"] for t in store.tiles])
        frame = alignment.frame
        store.set_doc("alignment", _jsonable(alignment.to_doc()))
    else:
        frame = Frame(math.radians(float(p.yaw)), origin)
    seconds["alignment"] = time.perf_counter() - t
    grid = Grid.for_store(store, frame, p.bin_width, p.z_bin)

    t = time.perf_counter()
    floors, slabs = find_storeys(z_hist, z_lo, p.slabs, p.min_storey_height)
    for d in slabs:
        d.position += frame.origin[2]
    ground = floor_levels(z_hist, z_lo, floors, p.z_bin)
    band_z = np.array([g + int(round(p.upper_band / p.z_bin)) for g in ground], dtype=np.int64)
    start = _initial_boxes(store, grid, floors)
    cells, walls, passes = slice_storeys(store, grid, floors, start, p.slicing_walls, band_z, client=client,
                                         max_levels=p.max_levels)
    seconds["slicing"] = time.perf_counter() - t

    t = time.perf_counter()
    edges = neighbour_edges(cells, p.walls.bins(p.min_face))
    floors_arr = np.array(floors, dtype=np.int64).reshape(-1, 2)
    test_edges(store, grid, floors_arr, cells, edges, p.walls, p.merge_window, band_z, client=client)
    comps = merge(cells, edges, p.bin_width, p.rules)
    seconds["merging"] = time.perf_counter() - t

    t = time.perf_counter()
    index = BoxIndex.build(floors_arr, np.array([c.row() for c in cells]).reshape(-1, 5))
    refs = _refine(store, grid, p, floors_arr, band_z, cells, comps.labels, index, client)
    plan = _RefinedPlan.build(cells, edges, comps.labels, refs, frame, p.bin_width)
    # a long building face between two refined spaces, cut where the new space on a side changes: its divider
    # was found on the whole face (a wall on one stretch); each piece is tested on its own stretch (a hallway
    # open across a line that is a wall between two rooms beside it).  Measured: hard set 0.939 -> 0.946
    # (h350 0.909 -> 0.928, h500-yaw33 0.961 -> 0.980), the clean set identical (0.9884).
    test_edges(store, grid, floors_arr, cells, [plan.edges[i] for i in plan.pieces], p.walls, p.merge_window,
               band_z, client=client)
    if p.rejoin:
        source = np.full(plan.n_spaces, -1, dtype=np.int64)
        for sp_id, (k, _) in plan.sub_of.items():
            source[sp_id] = k
        plan.regroup(rejoin_pieces(plan.cells, plan.edges, plan.labels, plan.sides, source, p.bin_width, p.rules))
    seconds["refining"] = time.perf_counter() - t

    t = time.perf_counter()
    n_spaces = plan.n_spaces
    store.add_dimensions([
        Dimension("cell_id", "int32", "result", "over-segmented cell of space parsing (-1: none)",
                  {"name": "cell_id", "type": "int32", "description": "space parsing cell"}),
        Dimension("space_id", "int32", "result", "space (room, hallway) of the point (-1: none)",
                  {"name": "space_id", "type": "int32", "description": "space id"}),
    ])
    sub = [(r, [(Grid.for_store(store, Frame(pt.yaw, origin), p.bin_width, p.z_bin),
                 pt.index(tuple(floors_arr[r.floor])), first) for pt, first in zip(r.parts, firsts)])
           for r, firsts in zip(plan.refinements, plan.firsts)]
    labelled = run_tasks(_label_tile, tiles, client=client, label="spaces: writing labels", keys=tiles,
                         extra_args=(store, grid, share(client, index), plan.labels,
                                     share(client, sub) if sub else sub, plan.owner))
    seconds["labelling"] = time.perf_counter() - t

    parse = _assemble(store, p, frame, floors, slabs + walls + plan.dividers, plan.cells, plan.edges,
                      plan.labels, labelled, tiles, n_spaces, plan)
    parse.stats = {"passes": passes, "cells": len(cells), "edges": len(edges),
                   "edges_divided": int(sum(e.divider is not None for e in edges)),
                   "refined": [{"space": r.space, "spaces": r.n_spaces,
                                "yaw_deg": [round(math.degrees(pt.yaw), 3) for pt in r.parts]}
                               for r in plan.refinements],
                   "refine_searched": len(refs),
                   "absorbed": len(comps.absorbed), "dropped": len(comps.dropped),
                   "merges_refused": len(comps.refused),
                   "seconds": {k: round(v, 3) for k, v in seconds.items()}}
    parse.stats["seconds"]["total"] = round(time.perf_counter() - t0, 3)
    store.set_doc(DOC, parse.to_doc())
    return parse


def _assemble(store, p: SpaceSettings, frame: Frame, floors: list[tuple[int, int]], dividers: list[FoundDivider],
              boxes: list[Box], edges: list[Edge], labels: np.ndarray, labelled: list[dict[str, Any]],
              tiles: list[str], n_spaces: int, plan: _RefinedPlan) -> SpaceParse:
    from engine.spaces.footprints import union_footprint, union_geojson

    bw, zb = p.bin_width, p.z_bin
    oz = frame.origin[2]
    cell_counts = np.zeros(len(boxes), dtype=np.int64)
    space_counts = np.zeros(n_spaces, dtype=np.int64)
    zmin, zmax = np.full(n_spaces, np.inf), np.full(n_spaces, -np.inf)
    touched: dict[int, list[str]] = defaultdict(list)
    for name, r in zip(tiles, labelled):
        np.add.at(cell_counts, r["cells"], r["counts"])
        sp = labels[r["cells"]]
        ok = sp >= 0
        np.add.at(space_counts, sp[ok], r["counts"][ok])
        np.minimum.at(zmin, sp[ok], r["zmin"][ok])
        np.maximum.at(zmax, sp[ok], r["zmax"][ok])
        for s in np.unique(sp[ok]):
            touched[int(s)].append(name)
    floor_list = [Floor(i, [oz + a * zb, oz + b * zb], 0) for i, (a, b) in enumerate(floors)]
    cells = []
    for i, b in enumerate(boxes):
        cells.append(Cell(i, b.floor, [b.u0 * bw, b.v0 * bw, b.u1 * bw, b.v1 * bw], int(cell_counts[i]),
                          int(labels[i]), plan.cell_yaw[i]))
        floor_list[b.floor].point_count += int(cell_counts[i])
    faces = _faces(frame, edges, plan.sides, plan.edge_yaw, floor_list, bw)
    nb_of: dict[int, list[int]] = defaultdict(list)
    for a, o in sorted(faces):
        nb_of[a].append(o)
    members_of: dict[int, list[int]] = defaultdict(list)
    for i, lab in enumerate(labels.tolist()):
        if lab >= 0:
            members_of[lab].append(i)
    def footprint(rects: list[list[float]], sub: tuple[int, float] | None) -> tuple[dict[str, Any], float]:
        if sub is None:
            return union_footprint(rects, frame)
        k, yaw = sub
        return clipped_footprint(rects, Frame(yaw, frame.origin), [cells[i].box for i in plan.clip[k]], frame)

    spaces = []
    for s in range(n_spaces):
        members = members_of[s]
        rects = [cells[i].box for i in members]
        if s in plan.joined:  # spaces joined after refinement: the union of their footprints
            parts = [footprint([cells[i].box for i in members if plan.before[i] == old], plan.sub_before.get(old))
                     for old in plan.joined[s]]
            fp, area = union_geojson([f for f, _ in parts])
        else:
            fp, area = footprint(rects, plan.sub_of.get(s))
        nbs = [Neighbour(o, faces[(s, o)]) for o in nb_of.get(s, [])]
        zr = ([float(zmin[s]), float(zmax[s])] if np.isfinite(zmin[s])
              else list(floor_list[boxes[members[0]].floor].z_range))
        spaces.append(Space(s, boxes[members[0]].floor, members, fp, area, zr, int(space_counts[s]),
                            touched.get(s, []), nbs))
    return SpaceParse(frame, bw, zb, floor_list, cells, dividers, spaces, point_count=int(store.meta.point_count),
                      unassigned_points=int(sum(r["unassigned"] for r in labelled)), params=p.to_dict())


def _faces(frame: Frame, edges: list[Edge], sides: np.ndarray, edge_yaw: list[float | None], floors: list[Floor],
           bw: float) -> dict[tuple[int, int], list[Face]]:
    """Shared faces between different spaces (both directions), contiguous pieces of one frame joined.

    ``sides[e]``: the space on each side of edge ``e``; ``edge_yaw[e]``: its frame (None: the building's).
    """
    pieces: dict[tuple[int, int], list[tuple]] = defaultdict(list)
    for e, (sa, sb), yaw in zip(edges, sides.tolist(), edge_yaw):
        if sa < 0 or sb < 0 or sa == sb:
            continue
        kind = e.divider.get("kind") if e.divider else None
        score = float(e.divider.get("score", 0.0)) if e.divider else None
        key = (min(sa, sb), max(sa, sb))
        pieces[key].append((math.nan if yaw is None else float(yaw), e.axis, e.position, e.overlap[0], e.overlap[1],
                            e.divider is not None, kind, score, e.floor))
    out: dict[tuple[int, int], list[Face]] = defaultdict(list)
    for key, items in pieces.items():
        items.sort(key=lambda x: (not math.isnan(x[0]), 0.0 if math.isnan(x[0]) else x[0], x[1], x[2], x[5], x[3]))
        joined: list[list] = []
        for it in items:
            last = joined[-1] if joined else None
            same_frame = (math.isnan(last[0]) and math.isnan(it[0])) or last[0] == it[0] if last else False
            if last and same_frame and last[1:3] == list(it[1:3]) and last[5] == it[5] and last[4] == it[3]:
                last[4] = it[4]
                if it[7] is not None:
                    last[7] = max(last[7] or 0.0, it[7])
            else:
                joined.append(list(it))
        faces = []
        for yaw, axis, pos, o0, o1, div, kind, score, floor in joined:
            fr = frame if math.isnan(yaw) else Frame(yaw, frame.origin)
            a = pos * bw
            ends = [[a, o0 * bw], [a, o1 * bw]] if axis == 0 else [[o0 * bw, a], [o1 * bw, a]]
            seg = fr.to_world(np.array(ends))
            faces.append(Face("u" if axis == 0 else "v", a, [o0 * bw, o1 * bw], list(floors[floor].z_range),
                              [[float(v) for v in seg[0]], [float(v) for v in seg[1]]], bool(div), kind, score,
                              None if math.isnan(yaw) else yaw))
        out[key] = faces
        out[(key[1], key[0])] = faces
    return out
