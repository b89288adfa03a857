"""Refining the large spaces of a parse in their own frame (issue 8: hard buildings).

After merging, every space of at least ``refine_min_area`` m² is parsed again
on its own points only (one task per space), in its own frame
(:mod:`engine.spaces.space_frames`), by the building's slicing and merging
(:mod:`engine.spaces.part`); when that splits the space, its pieces replace it.
Why and how: ``docs/design/spaces.md`` (refinement).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from engine.spaces.alignment import tile_evidence
from engine.spaces.histograms import BoxIndex, Grid, tile_extents, tiles_touching
from engine.spaces.memory_store import MemoryStore
from engine.spaces.part import Part, parse_part
from engine.spaces.slicing import Box
from engine.spaces.space_frames import Regions, frame_regions, space_yaw, two_orientations

if TYPE_CHECKING:
    from engine.spaces.settings import SpaceSettings


@dataclass
class Refinement:
    """A space parsed again: one part per frame (two for a space with a wing at an angle), and the
    regions that route its points to the parts (None: one part)."""

    space: int
    floor: int
    parts: list[Part] = field(default_factory=list)
    regions: Regions | None = None
    points: int = 0

    @property
    def n_spaces(self) -> int:
        return sum(pt.n_spaces for pt in self.parts)

    def part_of(self, xy_local: np.ndarray) -> np.ndarray:
        """Part of each store-local point."""
        if self.regions is None:
            return np.zeros(len(xy_local), dtype=np.int64)
        return self.regions.of(xy_local).astype(np.int64)


def gather_tile(job: tuple[str, np.ndarray], store, index: BoxIndex, grid: Grid) -> dict[str, np.ndarray]:
    """The raw ``x``, ``y``, ``z`` of one tile's points located in ``cells`` (``job``: tile, cell ids in the
    building's parse); a task of its own when spaces are refined on a cluster (:func:`refine_spaces`)."""
    tile, cells = job
    member = np.zeros(len(index.boxes) + 1, dtype=bool)
    member[np.asarray(cells, dtype=np.int64)] = True
    raw = store.read(tile, ("x", "y", "z"))
    box = index.locate(*grid.raw_bins(raw, grid.raw_affine(store.meta)))
    sel = member[box]  # box -1 -> the last entry (False)
    return {a: raw[a][sel] for a in "xyz"}


def _joined(pieces: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Per-tile pieces of a space's points, concatenated in tile order."""
    return {a: (np.concatenate([p[a] for p in pieces]) if pieces else np.zeros(0, np.int32)) for a in "xyz"}


def gather_space(store, tiles: list[str], index: BoxIndex, grid: Grid, cells: np.ndarray) -> dict[str, np.ndarray]:
    """The raw ``x``, ``y``, ``z`` of the points located in ``cells`` (ids in the building's parse)."""
    return _joined([gather_tile((t, cells), store, index, grid) for t in tiles])


def refine_space(item: dict[str, Any], store, index: BoxIndex, grid: Grid, params, floors: np.ndarray,
                 band_z: np.ndarray) -> Refinement:
    """Parse one space again on its own points, in its own frame(s) (one task).

    ``item``: ``space``, ``floor``, ``cells`` (its cell ids in the building's
    parse) and ``tiles`` (the tiles holding it); with ``pieces`` (the
    :func:`gather_tile` results of its tiles, in order) the points are not read again;
    ``pieces_points``: see :func:`engine.spaces.part.parse_part`.  ``params`` is the stage's
    :class:`engine.spaces.settings.SpaceSettings`.  When the space's walls follow two
    orientations (``refine_min_second``), it is split into the regions of each
    (:func:`frame_regions`) and each region is parsed in its own frame.
    """
    f = int(item["floor"])
    pieces = int(item.get("pieces_points") or 0)
    if "pieces" in item:  # gathered by one task per tile (refine_spaces)
        raw = _joined(item["pieces"])
    else:
        raw = gather_space(store, item["tiles"], index, grid, item["cells"])
    m = store.meta
    origin = tuple(grid.frame.origin)
    mem = MemoryStore(raw, m.scale, m.offset, origin)
    out = Refinement(int(item["space"]), f, points=len(raw["x"]))
    if out.points < 100:
        return out
    al = params.alignment
    xy = mem.xy_local()
    ev = tile_evidence(xy, al)
    found = two_orientations(ev["histogram"], al.angle_bin, params.refine_separation_deg, 2.0,
                             params.refine_min_second)
    if len(found) == 2:
        out.regions = frame_regions(xy, al, found, 2.0, params.refine_block, params.refine_smooth)
        region = out.regions.of(xy)
        if np.all(region == region[0]):
            out.regions = None
    if out.regions is None:
        yaw = space_yaw(xy, al, grid.frame.yaw, params.refine_snap_deg, evidence=ev)
        out.parts = [parse_part(mem, yaw, grid, params, f, floors, band_z, pieces)]
        return out
    for k in range(2):
        sel = region == k
        sub = MemoryStore({a: raw[a][sel] for a in "xyz"}, m.scale, m.offset, origin)
        yaw = space_yaw(sub.xy_local(), al, grid.frame.yaw, params.refine_snap_deg)
        out.parts.append(parse_part(sub, yaw, grid, params, f, floors, band_z, pieces))
    return out


def refine_spaces(items: list[dict[str, Any]], store, index: BoxIndex, grid: Grid, params, floors: np.ndarray,
                  band_z: np.ndarray, client=None) -> list[Refinement]:
    """:func:`refine_space` of every item (results in item order), largest space first, its points gathered
    by one task per tile.

    A space's refinement is one long task (its points in memory, recursive
    slicing in its own frame), and the space stage waits for the last one:
    with one large space, one worker parsed it while the others idled.  Three
    things shorten that wait without changing a result: the spaces start
    largest (most bins) first; the points of a space are read and located in
    its tiles by tasks of their own, spread over the workers (a quarter of the
    task's time on the medium ``bench_run`` building: 5.3 M points in 3 tiles);
    and the histogram passes of a space of at least
    ``buildingparser.spaces.refine-pieces-points`` points run as tasks over
    pieces of its points, one per worker thread (:class:`engine.spaces.memory_store.PieceStore`; most of
    the rest of the task).  Without a client: one after another here.
    """
    from engine import config
    from engine.spaces.histograms import share
    from tiles.tasks import run_tasks

    keys = [it["space"] for it in items]
    if client is None or not items:
        return run_tasks(refine_space, items, client=client, label="spaces: refining large spaces", keys=keys,
                         extra_args=(store, index, grid, params, floors, band_z))
    boxes = np.asarray(index.boxes, dtype=np.int64).reshape(-1, 5)
    bins = (boxes[:, 2] - boxes[:, 1]) * (boxes[:, 4] - boxes[:, 3])
    order = sorted(range(len(items)), key=lambda i: (-int(bins[np.asarray(items[i]["cells"], np.int64)].sum()), i))
    shared = share(client, index)
    retries = config.setting("retries")
    pieces_points = config.setting("spaces.refine-pieces-points") or 0
    jobs = [dict(items[i], pieces_points=pieces_points) for i in order]

    def with_pieces(job: dict[str, Any]) -> dict[str, Any]:
        """The job with its tiles' gather tasks as futures: the refinement task waits for them and receives
        their data."""
        pieces = client.map(gather_tile, [(t, job["cells"]) for t in job["tiles"]], store=store, index=shared,
                            grid=grid, pure=False, retries=retries)
        return dict(job, pieces=pieces)

    # One refinement per worker thread at a time, its gathers submitted with it: a refinement whose passes
    # run as tasks over pieces gives up its thread while it waits (worker_client), and with every job
    # submitted at once the next refinements and their gathers would start in that thread, holding the
    # points of many large spaces in memory together.
    threads = sum(int(w.get("nthreads", 1)) for w in client.scheduler_info()["workers"].values())
    done = run_tasks(refine_space, jobs, client=client, label="spaces: refining large spaces",
                     keys=[keys[i] for i in order], extra_args=(store, shared, grid, params, floors, band_z),
                     window=max(1, threads), prepare=with_pieces)
    out: list[Any] = [None] * len(items)
    for i, r in zip(order, done):
        out[i] = r
    return out


def refine_large_spaces(store, grid: Grid, p: SpaceSettings, floors: np.ndarray, band_z: np.ndarray,
                        cells: list[Box], labels: np.ndarray, index: BoxIndex, client,
                        skip: np.ndarray | None = None) -> list[Refinement]:
    """Every space of at least ``refine_min_area`` m² parsed again in its own frame (one task each).

    ``skip``: per storey, True where its spaces are not refined (no scanned floor: the refinement's ridges and
    ceiling steps read a ceiling and walls standing on a floor).
    """
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
        if skip is not None and skip[cells[members[0]].floor]:
            continue
        touch = tiles_touching(extents, floors, np.array([cells[i].row() for i in members]))
        items.append({"space": int(sp), "floor": int(cells[members[0]].floor), "cells": members,
                      "tiles": [names[i] for i in np.flatnonzero(touch)]})
    if not items:
        return []
    return refine_spaces(items, store, index, grid, p, floors, band_z, client)  # largest first, parallel reads
