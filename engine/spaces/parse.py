"""Space parsing of a whole building (paper section 3): the stage that turns a tile store into spaces.

Steps, each a batch of dask tasks over the tiles (nothing loads the building into one process; the driver only
sums small per-tile results): orientation evidence and z histogram, the aligned frame
(:mod:`engine.spaces.alignment`), storeys and recursive slicing (:mod:`engine.spaces.slicing`), merging
(:mod:`engine.spaces.merging`), refinement of the large spaces (:mod:`engine.spaces.refine`,
:mod:`engine.spaces.refined_plan`, :mod:`engine.spaces.rejoin`), the labels in every tile
(:mod:`engine.spaces.labelling`) and the ``meta/spaces`` document (:mod:`engine.spaces.assemble`,
:mod:`engine.spaces.document`).  The steps and the document are described in ``docs/design/spaces.md``.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from engine.spaces.alignment import AlignmentSettings, Frame, estimate_alignment, tile_evidence
from engine.spaces.assemble import assemble
from engine.spaces.bin_counts import CountedStore
from engine.spaces.document import DOC, SpaceParse, jsonable
from engine.spaces.histograms import BoxIndex, Grid, share, tiles_by_size, z_histogram
from engine.spaces.labelling import label_tile
from engine.spaces.merging import Components, Edge, merge, neighbour_edges, test_edges
from engine.spaces.refine import Refinement, refine_large_spaces
from engine.spaces.refined_plan import RefinedPlan
from engine.spaces.rejoin import rejoin_pieces
from engine.spaces.settings import SpaceSettings
from engine.spaces.slicing import Box, FoundDivider, find_storeys, floor_levels, floor_scanned, slice_storeys
from tiles.schema import Dimension
from tiles.store import TileStore
from tiles.tasks import run_tasks

if TYPE_CHECKING:
    from distributed import Client

logger = logging.getLogger(__name__)


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
    first, z_hist, z_lo, al = _evidence_and_z(store, tiles, p, client)
    seconds["first_pass"] = time.perf_counter() - t0

    t = time.perf_counter()
    frame = _frame(store, tiles, first, p, al, client)
    seconds["alignment"] = time.perf_counter() - t
    grid = Grid.for_store(store, frame, p.bin_width, p.z_bin)

    t = time.perf_counter()
    sl = _slice(store, grid, z_hist, z_lo, p, client)
    seconds["slicing"] = time.perf_counter() - t

    t = time.perf_counter()
    edges = neighbour_edges(sl.cells, p.walls.bins(p.min_face))
    test_edges(sl.counted, grid, sl.floors_arr, sl.cells, edges, p.walls, p.merge_window, sl.band_z, client=client,
               band_only=~sl.floor_scanned)
    comps = merge(sl.cells, edges, p.bin_width, p.rules, ~sl.floor_scanned)
    seconds["merging"] = time.perf_counter() - t

    t = time.perf_counter()
    index = BoxIndex.build(sl.floors_arr, np.array([c.row() for c in sl.cells]).reshape(-1, 5))
    refs = refine_large_spaces(store, grid, p, sl.floors_arr, sl.band_z, sl.cells, comps.labels, index, client,
                               ~sl.floor_scanned)
    plan = _refined_plan(grid, p, sl, edges, comps, refs, client)
    sl.counted.release()
    seconds["refining"] = time.perf_counter() - t

    t = time.perf_counter()
    labelled = _write_labels(store, grid, p, tiles, sl.floors_arr, index, plan, client)
    seconds["labelling"] = time.perf_counter() - t

    parse = assemble(store, p, frame, sl.floors, sl.slabs + sl.walls + plan.dividers, plan.cells, plan.edges,
                     plan.labels, labelled, tiles, plan.n_spaces, plan)
    parse.stats = _stats(sl, edges, comps, refs, plan, seconds)
    parse.stats["seconds"]["total"] = round(time.perf_counter() - t0, 3)
    store.set_doc(DOC, parse.to_doc())
    return parse


# -- the steps -----------------------------------------------------------------------------------------------

@dataclass
class _Slicing:
    """The storeys of a building and its cells after slicing."""

    floors: list[tuple[int, int]]  # z bins of each storey
    floors_arr: np.ndarray  # the same as an (n, 2) array
    slabs: list[FoundDivider]
    band_z: np.ndarray  # the z bin of each storey's upper band
    cells: list[Box]
    walls: list[FoundDivider]
    passes: list[dict[str, Any]]
    floor_scanned: np.ndarray  # per storey (:func:`engine.spaces.slicing.floor_scanned`)
    counted: CountedStore  # the tiles' bin counts, for the building's later passes (merging)


def _evidence_and_z(store: TileStore, tiles: list[str], p: SpaceSettings, client: Client | None
                    ) -> tuple[list[dict[str, Any]], np.ndarray, int, AlignmentSettings]:
    """One pass over the tiles: their orientation evidence and the building's z histogram (from bin ``z_lo``)."""
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
    return first, z_hist, z_lo, al


def _frame(store: TileStore, tiles: list[str], first: list[dict[str, Any]], p: SpaceSettings,
           al: AlignmentSettings, client: Client | None) -> Frame:
    """The aligned frame: the yaw estimated from the tiles' evidence (kept in ``meta/alignment``), or fixed."""
    origin = tuple(float(v) for v in store.meta.origin)
    if p.yaw is None:
        by_name = dict(zip(tiles, first))
        alignment = estimate_alignment(store, client=client, params=al,
                                       evidence=[by_name[t.name]["evidence"] for t in store.tiles])
        store.set_doc("alignment", jsonable(alignment.to_doc()))
        return alignment.frame
    return Frame(math.radians(float(p.yaw)), origin)


def _slice(store: TileStore, grid: Grid, z_hist: np.ndarray, z_lo: int, p: SpaceSettings, client: Client | None
           ) -> _Slicing:
    """Storeys from the z histogram, then recursive slicing of each along u and v."""
    floors, slabs = find_storeys(z_hist, z_lo, p.slabs, p.min_storey_height)
    for d in slabs:
        d.position += grid.frame.origin[2]
    ground, scanned = floor_scanned(z_hist, z_lo, floors, floor_levels(z_hist, z_lo, floors, p.z_bin), p.z_bin)
    for f, ok in enumerate(scanned):
        if not ok:
            logger.info("storey %d: no scanned floor (more than 5 %% of its points lie below its densest low "
                        "surface); walls are tested above door height only", f)
    band_z = np.array([g + int(round(p.upper_band / p.z_bin)) for g in ground], dtype=np.int64)
    start = _initial_boxes(store, grid, floors)
    floors_arr = np.array(floors, dtype=np.int64).reshape(-1, 2)
    # every later pass of the building reads each tile's points counted per (u, v, storey, band) bin
    counted = CountedStore(store, grid, BoxIndex.build(floors_arr, np.zeros((0, 5), np.int64)), band_z, client,
                           tiles_by_size(store))
    cells, walls, passes = slice_storeys(counted, grid, floors, start, p.slicing_walls, band_z, client=client,
                                         max_levels=p.max_levels, floor_scanned=np.array(scanned, dtype=bool))
    return _Slicing(floors, floors_arr, slabs, band_z, cells, walls, passes, np.array(scanned, dtype=bool), counted)


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


def _refined_plan(grid: Grid, p: SpaceSettings, sl: _Slicing, edges: list[Edge],
                  comps: Components, refs: list[Refinement], client: Client | None) -> RefinedPlan:
    """The refinements put in the building's plan, the cut faces tested again, the pieces rejoined."""
    plan = RefinedPlan.build(sl.cells, edges, comps.labels, refs, grid.frame, p.bin_width)
    # a long building face between two refined spaces, cut where the new space on a side changes: its divider
    # was found on the whole face (a wall on one stretch); each piece is tested on its own stretch (a hallway
    # open across a line that is a wall between two rooms beside it).  Measured: hard set 0.939 -> 0.946
    # (h350 0.909 -> 0.928, h500-yaw33 0.961 -> 0.980), the clean set identical (0.9884).
    test_edges(sl.counted, grid, sl.floors_arr, sl.cells, [plan.edges[i] for i in plan.pieces], p.walls, p.merge_window,
               sl.band_z, client=client, band_only=~sl.floor_scanned)
    if p.rejoin:
        source = np.full(plan.n_spaces, -1, dtype=np.int64)
        for sp_id, (k, _) in plan.sub_of.items():
            source[sp_id] = k
        plan.regroup(rejoin_pieces(plan.cells, plan.edges, plan.labels, plan.sides, source, p.bin_width, p.rules,
                                   across=~plan.frames_agree(), across_ratio=p.rejoin_across_frames))
    return plan


def _write_labels(store: TileStore, grid: Grid, p: SpaceSettings, tiles: list[str], floors_arr: np.ndarray,
                  index: BoxIndex, plan: RefinedPlan, client: Client | None) -> list[dict[str, Any]]:
    """``cell_id`` and ``space_id`` written in every tile (one task each); the tiles' counts and z ranges."""
    origin = tuple(float(v) for v in store.meta.origin)
    store.add_dimensions([
        Dimension("cell_id", "int32", "result", "over-segmented cell of space parsing (-1: none)",
                  {"name": "cell_id", "type": "int32", "description": "space parsing cell"}),
        Dimension("space_id", "int32", "result", "space (room, hallway) of the point (-1: none)",
                  {"name": "space_id", "type": "int32", "description": "space id"}),
    ])
    sub = [(r, [(Grid.for_store(store, Frame(pt.yaw, origin), p.bin_width, p.z_bin),
                 pt.index(tuple(floors_arr[r.floor])), first) for pt, first in zip(r.parts, firsts)])
           for r, firsts in zip(plan.refinements, plan.firsts)]
    return run_tasks(label_tile, tiles, client=client, label="spaces: writing labels", keys=tiles,
                     extra_args=(store, grid, share(client, index), plan.labels,
                                 share(client, sub) if sub else sub, plan.owner))


def _stats(sl: _Slicing, edges: list[Edge], comps: Components, refs: list[Refinement], plan: RefinedPlan,
           seconds: dict[str, float]) -> dict[str, Any]:
    """The ``stats`` of the document (without the total time)."""
    return {"passes": sl.passes, "cells": len(sl.cells), "edges": len(edges),
            "edges_divided": int(sum(e.divider is not None for e in edges)),
            "refined": [{"space": r.space, "spaces": r.n_spaces,
                         "yaw_deg": [round(math.degrees(pt.yaw), 3) for pt in r.parts]}
                        for r in plan.refinements],
            "refine_searched": len(refs),
            "absorbed": len(comps.absorbed), "dropped": len(comps.dropped),
            "merges_refused": len(comps.refused),
            "storeys_without_floor": [int(f) for f in np.flatnonzero(~sl.floor_scanned)],
            "seconds": {k: round(v, 3) for k, v in seconds.items()}}


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
